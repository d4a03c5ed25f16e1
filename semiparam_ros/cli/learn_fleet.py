"""``learn-fleet``: one checkpoint per robot of a folder of robots' bags, with a summary table.

::

    learn-fleet fleet/ --config-per-robot 'configs/{robot}.yaml' --out checkpoints/ --cluster local:2

``fleet/<robot>/`` holds each robot's bags; all but the last (in name order) are learned, the last is held
out and the frozen model's error on it is reported (``checkpoints/fleet.md`` and ``fleet.json``).
Argument parsing only; the work is done by :mod:`semiparam_ros.tune.fleet`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``learn-fleet``."""
    p = argparse.ArgumentParser(prog="learn-fleet", description="Learn one checkpoint per robot (a folder of "
                                "bags each) and report each frozen model on the robot's last bag.")
    p.add_argument("root", type=Path, help="folder with one folder of bags per robot")
    p.add_argument("--config-per-robot", required=True, metavar="PATTERN",
                   help="each robot's parameter file, {robot} standing for its folder's name")
    p.add_argument("--out", type=Path, required=True, help="output folder: <robot>.npz, fleet.md, fleet.json")
    p.add_argument("--jobs", type=int, default=1, help="robots learned in parallel here (-1: all cores)")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="a Dask scheduler address (tcp://host:8786) or local:N (docs/scale.md)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``learn-fleet``; returns the exit status (0 done, 2 invalid input or a failed robot, 1 I/O)."""
    args = build_parser().parse_args(argv)
    from semiparam_ros.tune.fleet import fleet_markdown, learn_fleet

    try:
        rows = learn_fleet(args.root, args.config_per_robot, args.out, jobs=args.jobs, cluster=args.cluster,
                           progress=not args.quiet)
    except (ValueError, OSError) as err:
        return error_exit("learn-fleet", err)
    print(fleet_markdown(rows), end="")
    print(f"wrote {args.out / 'fleet.md'} and {args.out / 'fleet.json'}")
    return 2 if any(r.status == "failed" for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
