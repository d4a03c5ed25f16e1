"""``real_robots``: P, NP and SP on a real arm's joint-torque logs, beside the usual references.

The references: the CAD model, batch identification (frozen and online), the learners frozen after
training, and persistence.

Defaults are those of the KUKA LWR4+ logs (``../shared/data/kuka_lwr4``: train on measurements_1, test on
measurements_3; friction-dominated joints 1, 5, 6, 7 of its README)::

    real_robots --data ../shared/data/kuka_lwr4 --json results/real_robots.json \
        --markdown results/real_robots.md

Argument parsing only; the work is done by :mod:`semiparam_ros.report.real_robot`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.cli.exit_codes import error_exit
from semiparam_ros.eval.protocol.options import DEFAULT_SPLITS

__all__ = ["build_parser", "main"]

_ROOT = Path(__file__).resolve().parents[2]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``real_robots``."""
    p = argparse.ArgumentParser(prog="real_robots", description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=_ROOT.parent / "shared" / "data" / "kuka_lwr4",
                   help="folder of the logs (default: ../shared/data/kuka_lwr4 beside the repository)")
    p.add_argument("--train", default="measurements_1", help="training bag inside --data")
    p.add_argument("--test", default="measurements_3", help="test bag inside --data")
    p.add_argument("--config", type=Path, default=_ROOT / "config" / "kuka_lwr4.yaml",
                   help="parameter file (default config/kuka_lwr4.yaml)")
    p.add_argument("--urdf", type=Path, default=None,
                   help="URDF (default: --data/kuka_lwr4_cogimon.urdf if present, else the configuration's)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter (repeatable)")
    p.add_argument("--friction-joints", nargs="*", default=None,
                   help="joints of the friction criterion (default: the KUKA's lwr_0, lwr_4, lwr_5, lwr_6)")
    p.add_argument("--splits", type=int, default=DEFAULT_SPLITS,
                   help="test parts of the protocol (default %(default)s)")
    p.add_argument("--no-inject", action="store_true", help="skip the external-torque measurement")
    p.add_argument("--horizons", nargs="*", default=None,
                   help="ages of the model for the horizon table [s] (0 = one step, 'frozen'); "
                        "none given = skip it (default: 0 0.1 1 10 frozen)")
    p.add_argument("--figure", type=Path, help="draw the error-by-age figure here (PNG)")
    p.add_argument("--served-figure", type=Path,
                   help="draw the served SP (frozen) against the measured torques of the test log here (PNG)")
    p.add_argument("--json", type=Path, help="write the JSON here")
    p.add_argument("--markdown", type=Path, help="write the markdown tables here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``real_robots``.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        0 on success, 2 on invalid input, 1 if a file cannot be read or written.
    """
    args = build_parser().parse_args(argv)
    from semiparam_ros.eval.protocol.horizon import DEFAULT_HORIZONS  # heavy imports after argument parsing
    from semiparam_ros.report.real_robot import run_comparison

    horizons = DEFAULT_HORIZONS if args.horizons is None else (args.horizons or None)

    try:
        text = run_comparison(data=args.data, config=args.config, train=args.train, test=args.test,
                              urdf=args.urdf,
                              overrides=parse_overrides(args.overrides), friction_joints=args.friction_joints,
                              splits=args.splits, inject=not args.no_inject,
                              horizons=horizons, json_path=args.json,
                              markdown_path=args.markdown, figure_path=args.figure,
                              served_figure_path=args.served_figure, progress=not args.no_progress)
    except (ValueError, OSError) as err:
        return error_exit("real_robots", err)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
