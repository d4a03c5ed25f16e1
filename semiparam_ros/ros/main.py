"""``estimator``'s command line: build the node, spin it, shut it down with its final checkpoint.

``ros2 run semiparam_ros estimator [--executor NAME] [--lifecycle] [--print-defaults] --ros-args …``.
"""

from __future__ import annotations

import argparse
import gc
import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import describe_parameters
from semiparam_ros.errors import StartupError
from semiparam_ros.ros.estimator_node import EstimatorNode
from semiparam_ros.ros.parameter_files import command_line_assignments, parameter_files

__all__ = ["EXECUTORS", "build_parser", "main", "parse_node_args", "spin"]

_SPIN_TIMEOUT_S = 0.1  # EventsExecutor.spin_once timeout (see spin())

#: Executors ``main`` can spin the node with (``--executor NAME``); the first is the default.
EXECUTORS: dict[str, Callable[..., Executor]] = {
    "events": EventsExecutor,
    "single_threaded": SingleThreadedExecutor,
}


def spin(executor: Executor, stop: threading.Event | None = None) -> None:
    """Spin until ``stop`` is set or the context shuts down.

    rclpy 7.1.6's ``EventsExecutor.spin()`` (and ``spin_once()`` without a timeout) runs no timer
    callback at all; ``spin_once`` with a timeout does, so both executors are driven by that loop, which
    also sees ``stop`` (set by the signal handlers of :func:`main`) within ``_SPIN_TIMEOUT_S``.
    """
    while rclpy.ok(context=executor.context) and not (stop is not None and stop.is_set()):
        executor.spin_once(timeout_sec=_SPIN_TIMEOUT_S)


def _first_line(err: BaseException) -> str:
    """Return the message of an rcl error without its C source locations (``…, at /project/src/…``)."""
    return str(err).split(", at /")[0].strip()


def _stop_on_signals(stop: threading.Event) -> None:
    """SIGINT and SIGTERM only set ``stop``: whatever callback runs finishes, then ``main`` shuts down.

    rclpy's own handlers would invalidate the context under a running callback (its publish fails) and
    Python's SIGINT raises KeyboardInterrupt wherever the main thread is; either reached the executor as
    an exception in a callback (logged FATAL) and could cost the final checkpoint.
    """
    def handler(signum: int, frame: Any) -> None:
        stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, handler)


def parse_node_args(args: list[str]) -> argparse.Namespace:
    """Parse the node's own options (those outside ``--ros-args``).

    Args:
        args: The command line without the program name and without ROS arguments.

    Returns:
        The options: ``executor`` (a key of :data:`EXECUTORS`), ``lifecycle``, ``print_defaults``.

    Raises:
        SystemExit: Unknown option or executor name (argparse prints the usage).
    """
    return build_parser().parse_args(args)


def build_parser() -> argparse.ArgumentParser:
    """Return the parser of the node's own options (``estimator --help``)."""
    parser = argparse.ArgumentParser(prog="estimator", description="semiparam_ros estimator node")
    parser.add_argument("--executor", choices=tuple(EXECUTORS), default=next(iter(EXECUTORS)),
                        help="rclpy executor spinning the node (default: %(default)s; measured in "
                             "docs/performance.md)")
    parser.add_argument("--lifecycle", action="store_true",
                        help="run as a managed (lifecycle) node: configure, activate, deactivate, cleanup")
    parser.add_argument("--print-defaults", action="store_true",
                        help="print every parameter with its type, range, default and meaning, and exit")
    return parser


#: What ``--print-defaults`` says before the parameters.
PARAMETERS_HEADER = (
    "# The estimator learns your robot's inverse dynamics from sensor_msgs/JointState on topics.joint_states "
    "(the joint\n# torques of JointState.effort, in N·m), or, when robot.ft_sensor names an F/T sensor, "
    "that sensor's\n# geometry_msgs/WrenchStamped on topics.wrench. It needs robot.urdf and robot.joints "
    "(no robot is assumed);\n# everything else below has a rate- and robot-independent default. Template: "
    "config/template.yaml.")


def main(args: list[str] | None = None) -> int:
    """Run the estimator node until shut down (Ctrl-C, SIGTERM or context shutdown).

    Args:
        args: Command-line arguments (``[--executor NAME] --ros-args ...``); ``sys.argv[1:]`` when None.

    Returns:
        Process exit code: 0 on a clean shutdown, 1 if its final checkpoint could not be written, 2 if the
        node could not start.

    Raises:
        Exception: A programming error inside a callback propagates out of ``spin`` (the ROS habit: the
            process dies with the traceback, and a launch file's ``respawn`` restarts it from the last
            periodic checkpoint); the node is destroyed without learning the queue or saving first.
    """
    argv = sys.argv[1:] if args is None else list(args)
    try:
        options = parse_node_args(rclpy.utilities.remove_ros_args(["estimator", *argv])[1:])
    except RuntimeError as err:  # rcl's RCLInvalidROSArgsError: a missing or unparseable parameter file
        print(f"[estimator] FATAL: invalid ROS arguments or parameter file: {_first_line(err)}",
              file=sys.stderr, flush=True)
        return 2
    if options.print_defaults:
        try:
            print(PARAMETERS_HEADER)
            print(describe_parameters(), flush=True)
        except BrokenPipeError:  # `estimator --print-defaults | head`: the reader had enough
            sys.stderr.close()
        return 0
    files = parameter_files(argv)
    # rcl lets a '/**' block of a parameter file beat '-p': the command line is given back to win
    overrides = [Parameter(name, value=value) for name, value in command_line_assignments(argv).items()]
    stop = threading.Event()
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    _stop_on_signals(stop)
    node: EstimatorNode | None = None
    code = 0
    crashed = False
    try:
        # One BLAS/OpenMP thread: the learner's small dense operations do not profit from more, and on a
        # small machine extra threads only compete with DDS and the checkpoint writer.
        with threadpool_limits(1):
            if options.lifecycle:
                from semiparam_ros.ros.lifecycle_node import LifecycleEstimatorNode

                node = LifecycleEstimatorNode(params_files=files, parameter_overrides=overrides)
            else:
                node = EstimatorNode(params_files=files, parameter_overrides=overrides)
            # Everything built so far (modules, compiled kernels, the model: ≈ 130 000 tracked objects)
            # lives as long as the process: out of the collector's reach, a full collection takes
            # ≈ 0.5 ms instead of ≈ 100 ms (a latency spike every few minutes at 1 kHz).
            gc.freeze()
            executor = EXECUTORS[options.executor]()
            executor.add_node(node)
            spin(executor, stop)
    except StartupError as err:
        print(f"[estimator] FATAL: {err}", file=sys.stderr, flush=True)
        code = 2
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as err:
        if node is None or node.context.ok():
            crashed = True
            raise
        # the signal handler invalidated the context under the executor: a shutdown, not a crash
        print(f"[estimator] shutting down (interrupted: {err})", file=sys.stderr, flush=True)
    except BaseException:
        crashed = True
        raise
    finally:
        if node is not None:
            if crashed:
                node.abort()
            else:
                node.shutdown()
                if not node.final_checkpoint_ok:
                    print("[estimator] ERROR: the final checkpoint could not be written (see the log above)",
                          file=sys.stderr, flush=True)
                    code = 1
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
