"""``tune``: select λ_P, λ_NP and σ for a given D by hold-out on a training bag.

::

    tune --train bags/generated/icub_xy --n-features 500 --holdout 0.2 --out results/tuned.yaml

Prints the grid (best first) and writes a ROS 2 parameter file — the input configuration with the selected
values — that the node (``--params-file``) and ``evaluate --config`` accept. Argument parsing only; the work
is done by :mod:`semiparam_ros.eval.tuning`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.errors import error_exit
from semiparam_ros.cli.evaluate import add_config_arguments, parse_overrides

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``tune``."""
    p = argparse.ArgumentParser(prog="tune", description="Hold-out grid search of parametric.lam, "
                                "nonparametric.lam and nonparametric.sigma for a given D.")
    p.add_argument("--train", type=Path, required=True, help="training bag (its last part is held out)")
    add_config_arguments(p)  # --config, --set (applied before tuning), topics
    p.add_argument("--n-features", type=int, default=None, help="D (default: nonparametric.n_features)")
    p.add_argument("--holdout", type=float, default=0.2, help="held-out fraction at the end (default 0.2)")
    p.add_argument("--lam-p", type=float, nargs="+", default=None, help="grid of parametric.lam")
    p.add_argument("--lam-np", type=float, nargs="+", default=None, help="grid of nonparametric.lam")
    p.add_argument("--sigma", type=float, nargs="+", default=None, help="grid of nonparametric.sigma")
    p.add_argument("--model", choices=("SP", "SPJ"), default="SP",
                   help="learner to tune: SP as configured (default) or SPJ, the joint semiparametric fit "
                        "(the written file then sets semiparametric.combination: joint)")
    p.add_argument("--limit", type=int, default=None, help="use only the first N samples of the bag")
    p.add_argument("--out", type=Path, default=None, help="write the tuned parameter file here")
    p.add_argument("--json", type=Path, default=None, help="write the grid as JSON here")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tune`` console script.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        Exit status: 0 on success, 2 on invalid input, 1 if a file cannot be read or written.
    """
    args = build_parser().parse_args(argv)
    from semiparam_ros.eval.run import run_tune  # heavy imports after argument parsing

    grid = {k: v for k, v in (("parametric.lam", args.lam_p), ("nonparametric.lam", args.lam_np),
                              ("nonparametric.sigma", args.sigma)) if v is not None}
    try:
        text = run_tune(train=args.train, config=args.config, overrides=parse_overrides(args.overrides),
                        joint_states_topic=args.joint_states_topic, wrench_topic=args.wrench_topic,
                        n_features=args.n_features, holdout=args.holdout, grid=grid, limit=args.limit,
                        out=args.out, json_path=args.json, progress=not args.no_progress, kind=args.model)
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("tune", err)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
