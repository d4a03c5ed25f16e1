"""semiparam_ros: online semiparametric inverse dynamics learning for ROS 2 Jazzy.

Subpackages:
    core: pure numerics and the message-to-sample pipeline (never imports rclpy or message packages).
    io: rosbag2 / MCAP reading and writing.
    sim: the synthetic iCub right-arm data generator.
    eval: offline bag-replay evaluation (the paper's protocol), figures, hyperparameter selection.
    ros: the thin rclpy node.
    cli: command-line entry points (argument parsing only).
"""

__version__ = "0.1.0"
