"""``excite``: design an excitation trajectory for identification and write it for a trajectory controller.

::

    excite --config config/panda.yaml --duration 20 --out traj.yaml
    excite --config config/ur5.yaml --duration 30 --out traj.mcap --margin 0.2 --max-acceleration 3
    excite --config my_robot.yaml --duration 20 --out traj.yaml --limit wrist_3_joint.lower=-3.14 \
        --limit wrist_3_joint.upper=3.14

Minimises the condition number of the base regressor of the configured model (friction and offsets
included) over a periodic Fourier trajectory inside the URDF's limits and a margin; writes the
``JointTrajectory`` (``.yaml`` message fields, or an ``.mcap`` bag) and ``<name>.excitation.yaml`` (its
coefficients, condition number and each base parameter's σ). Self-collision is not checked: narrow the
limits where the arm could hit itself or its surroundings. Exit status 2 for invalid or infeasible input,
1 for a file that cannot be written. Argument parsing only (:mod:`semiparam_ros.core.rigid_body.excitation`).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``excite``."""
    p = argparse.ArgumentParser(prog="excite", description="Design a periodic excitation trajectory that "
                                "minimises the base regressor's condition number under the URDF's limits, "
                                "and write it as a JointTrajectory.")
    p.add_argument("--config", type=Path, required=True, help="the node's ROS 2 parameter file")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter of the file (repeatable)")
    p.add_argument("--duration", type=float, required=True, help="length of the trajectory (s)")
    p.add_argument("--out", type=Path, required=True, help="traj.yaml (message fields) or traj.mcap (a bag)")
    p.add_argument("--period", type=float, default=10.0,
                   help="wished period (s; adjusted to divide the duration, default %(default)s)")
    p.add_argument("--harmonics", type=int, default=6, help="harmonics per joint (default %(default)s)")
    p.add_argument("--margin", type=float, default=0.1,
                   help="fraction of each position range, velocity, acceleration and effort limit kept free "
                   "(default %(default)s)")
    p.add_argument("--max-acceleration", type=float, default=None,
                   help="largest |q̈| of every joint (rad/s²; default: bounded by the efforts only)")
    p.add_argument("--limit", action="append", default=[], metavar="JOINT.KIND=VALUE",
                   help="set or replace a limit (KIND: lower, upper, velocity, acceleration, effort; rad, "
                   "rad/s, rad/s², N·m), e.g. for a joint the URDF leaves unlimited (repeatable)")
    p.add_argument("--iterations", type=int, default=200,
                   help="optimiser iterations (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the optimiser's starts (default %(default)s)")
    p.add_argument("--point-rate", type=float, default=100.0,
                   help="trajectory points per s (default %(default)s)")
    p.add_argument("--lead-in", type=float, default=5.0,
                   help="time before the first point, for the controller to reach it (s, default "
                   "%(default)s)")
    p.add_argument("--topic", default=None, help="topic of the .mcap bag (default "
                   "/joint_trajectory_controller/joint_trajectory)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``excite``; returns the exit status (0 done, 2 invalid or infeasible input, 1 an I/O failure)."""
    args = build_parser().parse_args(argv)
    from threadpoolctl import threadpool_limits

    from semiparam_ros.core.config import load_config
    from semiparam_ros.core.estimator.build import build_regressor
    from semiparam_ros.core.rigid_body.excitation import ExcitationLimits, design_excitation
    from semiparam_ros.io.trajectory_files import DEFAULT_TOPIC, write_excitation

    try:
        overrides: dict[str, float] = {}
        for key, value in parse_overrides(args.limit, "--limit").items():
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise ValueError(f"--limit {key}: expected a number, got {value!r}")
            overrides[key] = float(value)
        config = load_config(args.config).with_overrides(parse_overrides(args.overrides))
        regressor = build_regressor(config)
        limits = ExcitationLimits.from_regressor(regressor, margin=args.margin,
                                                 max_acceleration=args.max_acceleration, overrides=overrides)
        # One BLAS thread: the SVDs are small (hundreds of rows × the base parameters), a second thread
        # gains nothing alone and two excite runs sharing two cores each with two threads ran 15× slower.
        with threadpool_limits(1):
            excitation = design_excitation(regressor, limits, duration=args.duration, period=args.period,
                                           n_harmonics=args.harmonics, iterations=args.iterations,
                                           seed=args.seed)
        print(excitation.summary())
        written = write_excitation(args.out, excitation, point_rate=args.point_rate, lead_in=args.lead_in,
                                   topic=args.topic or DEFAULT_TOPIC, overwrite=args.overwrite)
    except (ValueError, OSError) as err:
        return error_exit("excite", err)
    for path in written:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
