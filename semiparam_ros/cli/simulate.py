"""``simulate``: write synthetic robot recordings as rosbag2/MCAP bags.

Examples::

    simulate --out bags/generated                      # default preset: icub_xy, icub_xz, icub_payload, 60 s
    simulate --out bags/generated --preset paper       # 1000 s, wrench 10 Hz (10 000 samples), joints 100 Hz
    simulate --out /tmp/b --scenario xy --duration 10 --no-effects --no-noise   # clean rigid-body bag
    simulate --out bags/generated --scenario contacts  # icub_contacts: 120 s, contacts, then a 0.5 kg pickup
    simulate --robot panda --rate 1000 --out bags/generated   # panda_excitation_1000hz, panda_payload_1000hz
    simulate --robot ur5 --rate 100 --scenario contacts --contact-rate 6 --out bags/generated

Argument parsing only; the work is done by :mod:`semiparam_ros.sim`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``simulate``."""
    p = argparse.ArgumentParser(
        prog="simulate",
        description="Simulate the iCub right arm (F/T sensor: circles in XY/XZ, multi-sine, payload pickup, "
        "contacts) or a joint-torque arm (Panda, UR5: multi-sine, friction, payload, contacts) and "
        "write rosbag2/MCAP bags with /joint_states, /wrench (iCub) and ground-truth topics.",
    )
    p.add_argument("--out", default="bags/generated", help="parent folder of the bags (default: %(default)s)")
    p.add_argument(
        "--robot",
        choices=("icub", "panda", "ur5"),
        help="icub: F/T sensor in the upper arm; panda, ur5: measured joint torques (default icub)",
    )
    p.add_argument(
        "--urdf",
        help="simulate the joint torques of this URDF's arm instead of a preset (a file path, package://…, "
        "example-robot-data://…; with --joints): friction, offsets and noise scaled to its gravity torques; "
        "a parameter file for learn is written beside each bag (params.yaml)",
    )
    p.add_argument("--joints", nargs="+", metavar="JOINT", help="with --urdf: the moving joints, in order")
    p.add_argument("--end-effector", help="with --urdf: the frame payloads and contacts act at (default: the "
                   "child link of the last joint)")
    p.add_argument("--ft-sensor", metavar="JOINT", help="with --urdf: a fixed joint holding a six-axis F/T "
                   "sensor; its wrench is recorded on /wrench too and the parameter file learns it")
    p.add_argument(
        "--rate",
        type=float,
        help="sampling rate (Hz): joint states of an arm (default 1000), both streams of the iCub",
    )
    p.add_argument(
        "--preset",
        choices=("default", "paper"),
        default="default",
        help="default: 60 s, both streams 100 Hz; paper: 1000 s, wrench 10 Hz, joint states 100 Hz",
    )
    p.add_argument(
        "--scenario",
        action="append",
        choices=("xy", "xz", "payload", "multisine", "contacts", "excitation"),
        help="scenario to write (repeatable). iCub: xy, xz, payload, multisine, contacts (default xy, xz, "
        "payload); arms: excitation, payload, contacts (default excitation, payload). contacts: contact "
        "episodes in [0.15, 0.65]·T then a payload pickup at 0.75·T, T = 120 s unless --duration",
    )
    p.add_argument("--duration", type=float, help="length of each bag (s)")
    p.add_argument("--samples", type=int, help="number of wrench samples (sets the duration)")
    p.add_argument("--joint-rate", type=float, help="joint-state rate (Hz)")
    p.add_argument("--wrench-rate", type=float, help="wrench rate (Hz)")
    p.add_argument("--delay", type=float, help="wrench sampled this many s after the joint states")
    p.add_argument("--radius", type=float, help="circle radius (m, default 0.10)")
    p.add_argument("--speed", type=float, help="hand speed (m/s, default 0.6)")
    p.add_argument("--seed", type=int, help="seed of noise and multi-sine (default 0)")
    p.add_argument(
        "--payload-mass", type=float, help="payload mass (kg; default 0.5 iCub, 1.0 Panda, 1.5 UR5)"
    )
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
    p.add_argument(
        "--no-effects",
        action="store_true",
        help="no non-rigid effects: rigid-body wrench only (iCub), no friction, offsets or armature (arms)",
    )
    c = p.add_argument_group("contact episodes (scenario contacts)")
    c.add_argument("--contact-rate", type=float, help="episodes per minute (default 4)")
    c.add_argument(
        "--contact-force", type=float, nargs=2, metavar=("MIN", "MAX"), help="peak force (N, 5 30)"
    )
    c.add_argument(
        "--contact-duration", type=float, nargs=2, metavar=("MIN", "MAX"), help="duration (s, default 0.2 3)"
    )
    c.add_argument(
        "--contact-window",
        type=float,
        nargs=2,
        metavar=("START", "END"),
        help="time span holding the episodes (s; default 0.15·T to 0.65·T)",
    )
    a = p.add_argument_group("joint-torque arms (--robot panda|ur5)")
    a.add_argument(
        "--friction-scale", type=float, help="factor on friction, offsets and armature (default 1)"
    )
    a.add_argument("--armature", type=float, help="armature of every joint (kg·m², default 0)")
    a.add_argument(
        "--perturbation",
        type=float,
        nargs=3,
        metavar=("MASS", "INERTIA", "COM"),
        help="true vs URDF parameters: relative mass, inertia change, COM shift (m); default 0.15 0.15 0.01",
    )
    a.add_argument("--no-perturbation", action="store_true", help="true parameters = the URDF's")
    a.add_argument("--trajectory", help="drive the arm on this excitation (excite's traj.yaml, traj.mcap or "
                   "traj.excitation.yaml; repeated for the duration) instead of a random multi-sine")
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
    args = vars(build_parser().parse_args(argv))
    out, overwrite, compress, quiet = args.pop("out"), args.pop("overwrite"), not args.pop("no_compress"), \
        args.pop("quiet")
    from semiparam_ros.sim.generate import SimulationOptions, simulate_bags  # heavy imports after parsing

    try:
        options = SimulationOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in args.items()})
        paths = simulate_bags(options, out, overwrite=overwrite, compress=compress, progress=not quiet)
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("simulate", err)
    for path in paths:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
