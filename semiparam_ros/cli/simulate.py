"""``simulate``: write synthetic iCub right-arm recordings as rosbag2/MCAP bags.

Examples::

    simulate --out bags/generated                      # default preset: icub_xy, icub_xz, icub_payload, 60 s
    simulate --out bags/generated --preset paper       # 1000 s, wrench 10 Hz (10 000 samples), joints 100 Hz
    simulate --out /tmp/b --scenario xy --duration 10 --no-effects --no-noise   # clean rigid-body bag

Argument parsing only; the work is done by :mod:`semiparam_ros.sim`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from semiparam_ros.cli.errors import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``simulate``."""
    p = argparse.ArgumentParser(
        prog="simulate",
        description="Simulate the iCub right arm (circles in XY/XZ, multi-sine, payload pickup) and write "
        "rosbag2/MCAP bags with /joint_states, /wrench and ground-truth topics.",
    )
    p.add_argument("--out", default="bags/generated", help="parent folder of the bags (default: %(default)s)")
    p.add_argument(
        "--preset",
        choices=("default", "paper"),
        default="default",
        help="default: 60 s, both streams 100 Hz; paper: 1000 s, wrench 10 Hz, joint states 100 Hz",
    )
    p.add_argument(
        "--scenario",
        action="append",
        choices=("xy", "xz", "payload", "multisine"),
        help="scenario to write (repeatable; default: xy, xz, payload)",
    )
    p.add_argument("--duration", type=float, help="length of each bag (s)")
    p.add_argument("--samples", type=int, help="number of wrench samples (sets the duration)")
    p.add_argument("--joint-rate", type=float, help="joint-state rate (Hz)")
    p.add_argument("--wrench-rate", type=float, help="wrench rate (Hz)")
    p.add_argument("--delay", type=float, help="wrench sampled this many s after the joint states")
    p.add_argument("--radius", type=float, help="circle radius (m, default 0.10)")
    p.add_argument("--speed", type=float, help="hand speed (m/s, default 0.6)")
    p.add_argument("--seed", type=int, help="seed of noise and multi-sine (default 0)")
    p.add_argument("--payload-mass", type=float, default=0.5, help="payload mass (kg, default %(default)s)")
    p.add_argument("--payload-time", type=float, help="pickup time (s from the start; default: middle)")
    p.add_argument(
        "--payload-trajectory",
        choices=("xy", "xz", "multisine"),
        default="xy",
        help="trajectory of the payload scenario (default %(default)s)",
    )
    p.add_argument(
        "--speed-variation",
        type=float,
        default=None,
        help="relative amplitude of the slow hand-speed modulation on the circles (default 0.15)",
    )
    p.add_argument(
        "--centre-wander",
        type=float,
        default=None,
        help="slow wander of the circle centre per axis (m, default 0.01)",
    )
    p.add_argument(
        "--radius-wander", type=float, default=None, help="slow wander of the circle radius (m, default 0.01)"
    )
    p.add_argument(
        "--no-variability", action="store_true", help="circles repeat exactly (no speed/centre/radius wander)"
    )
    p.add_argument(
        "--effects-scale",
        type=float,
        default=1.0,
        help="factor on all non-rigid effects (on top of the calibrated defaults)",
    )
    p.add_argument("--noise-scale", type=float, default=1.0, help="factor on all noise levels")
    p.add_argument("--no-effects", action="store_true", help="no non-rigid effects (rigid-body wrench only)")
    p.add_argument("--no-noise", action="store_true", help="no noise on joints and wrench")
    p.add_argument("--overwrite", action="store_true", help="replace existing bag folders")
    p.add_argument("--no-compress", action="store_true", help="do not zstd-compress the MCAP chunks")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``simulate``.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        0 on success, 2 on invalid arguments, 1 if a bag cannot be written.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    from semiparam_ros.sim.effects import DEFAULT_EFFECTS
    from semiparam_ros.sim.generate import generate
    from semiparam_ros.sim.scenario import DEFAULT_VARIABILITY, PRESETS, TrajectoryVariability, preset_configs

    try:
        effects = DEFAULT_EFFECTS.scaled(
            0.0 if args.no_effects else args.effects_scale, 0.0 if args.no_noise else args.noise_scale
        )
        if args.no_variability:
            variability = TrajectoryVariability(speed=0.0, centre=0.0, radius=0.0)
        else:
            variability = TrajectoryVariability(
                speed=DEFAULT_VARIABILITY.speed if args.speed_variation is None else args.speed_variation,
                centre=DEFAULT_VARIABILITY.centre if args.centre_wander is None else args.centre_wander,
                radius=DEFAULT_VARIABILITY.radius if args.radius_wander is None else args.radius_wander,
                min_period=DEFAULT_VARIABILITY.min_period,
                max_period=DEFAULT_VARIABILITY.max_period,
                components=DEFAULT_VARIABILITY.components,
            )
        duration = args.duration
        if args.samples is not None:
            if args.samples <= 0:
                raise ValueError("--samples must be positive")
            rate = args.wrench_rate or PRESETS[args.preset]["wrench_rate"]
            duration = args.samples / rate
        configs = preset_configs(
            args.preset,
            tuple(args.scenario or ("xy", "xz", "payload")),
            effects=effects,
            payload_mass=args.payload_mass,
            payload_trajectory=args.payload_trajectory,
            duration=duration,
            joint_rate=args.joint_rate,
            wrench_rate=args.wrench_rate,
            delay=args.delay,
            radius=args.radius,
            speed=args.speed,
            seed=args.seed,
            payload_time=args.payload_time,
            variability=variability,
        )
        paths = generate(
            args.out,
            configs,
            overwrite=args.overwrite,
            compress=not args.no_compress,
            progress=not args.quiet,
        )
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("simulate", err)
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
