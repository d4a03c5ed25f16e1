"""``tune``: select λ_P, λ_NP and σ for a given D on a training bag (hold-out or the paper's protocol).

::

    tune --train bags/generated/icub_xy --n-features 500 --holdout 0.2 --out results/tuned.yaml
    tune --train bags/generated/icub_xy --method protocol --models NP SP SPJ --train-n 5000 --splits 5 \
        --split-size 1000 --lam-np 0.001 0.01 --sigma 4 6 --jobs -1 --json results/select.json
    tune --train robot_a/log_1 robot_b/log_1 --validate robot_c/log_1 --config arm.yaml --cluster local:2

Prints the grid (best first) and writes a ROS 2 parameter file — the input configuration with the selected
values — that the node (``--params-file``) and ``evaluate --config`` accept. Works for every
``robot.output`` (wrench or joint torques). Argument parsing only; the work is done by
:mod:`semiparam_ros.tune.selection`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from semiparam_ros.cli.evaluate import add_config_arguments, parse_overrides
from semiparam_ros.cli.exit_codes import error_exit
from semiparam_ros.eval.protocol.options import DEFAULT_WINDOW_S

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``tune``."""
    p = argparse.ArgumentParser(
        prog="tune",
        description="Grid search of parametric.lam, nonparametric.lam "
        "and nonparametric.sigma for a given D, by hold-out or by the paper's protocol "
        "within the training bag.",
    )
    p.add_argument("--train", type=Path, nargs="+", required=True,
                   help="training bag (its last part is held out); with --validate: the bags learned")
    p.add_argument("--validate", type=Path, nargs="+", default=None,
                   help="select by held-out motion: score every grid point on these other bags (one step, "
                        "0.1 s, 1 s, 10 s and frozen as served) after learning --train")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run the grid points on a Dask cluster: a scheduler address (tcp://host:8786) or "
                        "local:N for N worker processes here (same numbers as --jobs 1; docs/scale.md)")
    add_config_arguments(p)  # --config, --set (applied before tuning), topics
    p.add_argument("--n-features", type=int, default=None, help="D (default: nonparametric.n_features)")
    p.add_argument("--holdout", type=float, default=0.2, help="held-out fraction at the end (default 0.2)")
    p.add_argument("--lam-p", type=float, nargs="+", default=None, help="grid of parametric.lam")
    p.add_argument("--lam-np", type=float, nargs="+", default=None, help="grid of nonparametric.lam")
    p.add_argument("--sigma", type=float, nargs="+", default=None, help="grid of nonparametric.sigma")
    p.add_argument(
        "--model",
        choices=("SP", "SPJ"),
        default="SP",
        help="learner to tune: SP as configured (default) or SPJ, the joint semiparametric fit "
        "(the written file then sets semiparametric.combination: joint)",
    )
    p.add_argument(
        "--method",
        choices=("holdout", "protocol"),
        default="holdout",
        help="holdout (default): learn the first part, predict the held-out end; protocol: the "
        "paper's protocol within the bag (train on --train-n samples, test-then-train on "
        "--splits parts of the rest), every --models learner at every grid point",
    )
    p.add_argument(
        "--models",
        nargs="+",
        choices=("P", "NP", "SP", "SPJ"),
        default=None,
        help="protocol method: learners run and selected for at every point (default: --model)",
    )
    p.add_argument(
        "--train-n", type=int, default=None, help="protocol method: training samples (default: half the bag)"
    )
    p.add_argument("--splits", type=int, default=5, help="protocol method: test parts (default 5)")
    p.add_argument("--split-size", type=int, default=None, help="protocol method: samples per part")
    p.add_argument("--window", type=float, default=DEFAULT_WINDOW_S,
                   help="protocol method: RMSE window [s] (default %(default)s)")
    p.add_argument(
        "--jobs",
        type=int,
        default=-1,
        help="grid points run in parallel (default -1: all cores; 1: serial); same numbers",
    )
    p.add_argument("--limit", type=int, default=None, help="use only the first N samples of the bag")
    p.add_argument("--out", type=Path, default=None, help="write the tuned parameter file here")
    p.add_argument("--json", type=Path, default=None, help="write the grid as JSON here")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (one is drawn only when stderr is a terminal anyway)",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tune`` console script.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        Exit status: 0 on success, 2 on invalid input, 1 if a file cannot be read or written.
    """
    args = build_parser().parse_args(argv)
    from semiparam_ros.tune.tuning import run_tune  # heavy imports after argument parsing

    grid = {
        k: v
        for k, v in (
            ("parametric.lam", args.lam_p),
            ("nonparametric.lam", args.lam_np),
            ("nonparametric.sigma", args.sigma),
        )
        if v is not None
    }
    try:
        text = run_tune(
            train=args.train,
            config=args.config,
            overrides=parse_overrides(args.overrides),
            joint_states_topic=args.joint_states_topic,
            wrench_topic=args.wrench_topic,
            n_features=args.n_features,
            holdout=args.holdout,
            grid=grid,
            limit=args.limit,
            out=args.out,
            json_path=args.json,
            progress=not args.no_progress,
            kind=args.model,
            method=args.method,
            kinds=args.models,
            train_n=args.train_n,
            splits=args.splits,
            split_size=args.split_size,
            window_s=args.window,
            jobs=args.jobs,
            validate=args.validate,
            cluster=args.cluster,
        )
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("tune", err)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
