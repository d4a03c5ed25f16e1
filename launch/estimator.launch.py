"""Launch the semiparam_ros estimator node.

    ros2 launch semiparam_ros estimator.launch.py params_file:=/path/to/my_arm.yaml namespace:=arm \
        joint_states:=/my_arm/joint_states wrench:=/my_arm/ft use_sim_time:=false

Arguments: ``params_file`` (required: your robot's ROS 2 parameter file keyed ``/**:``, e.g. a copy of
``config/template.yaml``; the paper's iCub is ``config/icub_right_arm.yaml``), ``namespace`` (of the node
and its ``~/`` topics), ``joint_states`` and ``wrench`` (the input topics, remapped), ``use_sim_time``,
``executor`` (``events`` or ``single_threaded``).
"""

from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    """Declare the arguments and the ``estimator`` node."""
    return LaunchDescription([
        DeclareLaunchArgument("params_file",
                              description="ROS 2 parameter file of the estimator, keyed '/**:' (robot.urdf, "
                                          "robot.joints, robot.output, ...)"),
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the node"),
        DeclareLaunchArgument("joint_states", default_value="joint_states",
                              description="sensor_msgs/JointState input topic"),
        DeclareLaunchArgument("wrench", default_value="wrench",
                              description="geometry_msgs/WrenchStamped input topic (F/T sensor output)"),
        DeclareLaunchArgument("use_sim_time", default_value="false", description="use /clock"),
        DeclareLaunchArgument("executor", default_value="events",
                              description="rclpy executor: events or single_threaded"),
        Node(
            package="semiparam_ros",
            executable="estimator",
            name="estimator",
            namespace=LaunchConfiguration("namespace"),
            arguments=["--executor", LaunchConfiguration("executor")],
            parameters=[LaunchConfiguration("params_file"),
                        {"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"),
                                                        value_type=bool)}],
            remappings=[("joint_states", LaunchConfiguration("joint_states")),
                        ("wrench", LaunchConfiguration("wrench"))],
            output="screen",
            emulate_tty=True,
        ),
    ])
