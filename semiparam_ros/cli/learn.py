"""``learn``: learn a model offline from recorded bags and write a checkpoint.

::

    learn bag1 bag2 --config config/kuka_lwr4.yaml --checkpoint kuka.npz
    learn new_bag --config config/kuka_lwr4.yaml --init kuka.npz --checkpoint kuka2.npz --json report.json

The bags go through the node's own pipeline and estimator (:mod:`semiparam_ros.serving.bag_learning`), so the
checkpoint is the one the node would have written after hearing them live; the node warm starts from it
(``checkpoint.path``) and :func:`semiparam_ros.load_model` reads it. Argument parsing only.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``learn``."""
    p = argparse.ArgumentParser(prog="learn", description="Learn recorded bags offline through the node's "
                                "pipeline and write a self-contained checkpoint.")
    p.add_argument("bags", nargs="+", type=Path, help="bag folders or .mcap files, learned in this order")
    p.add_argument("--config", type=Path, required=True, help="the node's ROS 2 parameter file")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
                   help="override a parameter, e.g. --set nonparametric.n_features=200 (repeatable)")
    p.add_argument("--checkpoint", type=Path, required=True, help="checkpoint to write (atomically)")
    p.add_argument("--init", type=Path, default=None, help="continue from this checkpoint")
    p.add_argument("--joint-states-topic", help="JointState topic (default: /<topics.joint_states>)")
    p.add_argument("--wrench-topic", help="WrenchStamped topic (default: /<topics.wrench>)")
    p.add_argument("--json", type=Path, default=None, help="write the run's report as JSON here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _progress_printer() -> object:
    from semiparam_ros.serving.bag_learning import LearnProgress

    tty = sys.stderr.isatty()

    def show(p: LearnProgress) -> None:
        share = p.messages / p.total_messages if p.total_messages else 0.0
        speed = p.log_s / p.wall_s if p.wall_s > 0 else 0.0
        width = 30
        bar = "#" * int(width * min(share, 1.0))
        text = (f"bag {p.bag_index + 1}/{p.n_bags} [{bar:<{width}}] {100 * share:5.1f} %  "
                f"{p.samples} samples  {speed:.1f}x real time")
        if tty:
            print("\r" + text, end="", file=sys.stderr, flush=True)

    return show


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``learn``; returns the exit status (0 done, 2 invalid input, 1 an I/O failure)."""
    args = build_parser().parse_args(argv)
    from semiparam_ros.core.config import load_config
    from semiparam_ros.serving.bag_learning import learn_bags

    try:
        config = load_config(args.config).with_overrides(parse_overrides(args.overrides))
        _, report = learn_bags(args.bags, config, checkpoint=args.checkpoint, init=args.init,
                               joint_states_topic=args.joint_states_topic, wrench_topic=args.wrench_topic,
                               progress=None if args.quiet else _progress_printer())  # type: ignore[arg-type]
    except (ValueError, OSError) as err:
        return error_exit("learn", err)
    if not args.quiet and sys.stderr.isatty():
        print(file=sys.stderr)
    drops = ", ".join(f"{k} {v}" for k, v in report.drops.items()) or "none"
    print(f"learned {report.learned} of {report.samples} samples from {len(report.bags)} bag(s) "
          f"({report.log_s:.1f} s recorded) in {report.wall_s:.1f} s ({report.realtime_factor:.1f}x real "
          f"time); drops: {drops}; wrote {report.checkpoint}")
    for bag in report.recovered:
        print(f"warning: {bag} was truncated or corrupt: read as far as possible, samples were lost",
              file=sys.stderr)
    for text in report.warnings:
        print(f"warning: {text}", file=sys.stderr)
    if report.fit is not None and not args.quiet:
        print(report.fit.text())
    if args.json is not None:
        from semiparam_ros.atomic import atomic_open

        summary = {"bags": report.bags, "messages": report.messages, "samples": report.samples,
                   "learned": report.learned, "drops": report.drops, "not_learned": report.not_learned,
                   "wall_s": report.wall_s, "log_s": report.log_s, "realtime_factor": report.realtime_factor,
                   "recovered": report.recovered, "checkpoint": report.checkpoint,
                   "warnings": report.warnings, "fit": None if report.fit is None else report.fit.as_dict()}
        with atomic_open(args.json, "w") as fh:
            json.dump(summary, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
