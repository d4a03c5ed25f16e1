"""``evaluate``: replay bags through the estimator's core and reproduce the paper's experiment.

Paper protocol (P, NP, SP from zero; train on all of --train; test-then-train on --splits parts of --test)::

    evaluate --train bags/generated/icub_xy --test bags/generated/icub_xz --split-size 1000 \
        --json results/report.json --plot results/fig3.png

Add ``--models P NP SP SPJ SPC`` to compare the default (consistent) SP with the joint semiparametric fit
(``SPJ``) and the paper's cascade (``SPC``).

Payload scenario (one bag with a pickup; SP with and without forgetting)::

    evaluate --payload bags/icub_payload --forgetting 0.995 --json results/payload.json \
        --plot results/payload.png

Contact evaluation (a ``simulate --scenario contacts`` log: the node's estimator with the gate on and off;
contact detection per episode, the error after the contacts vs before, payload adoption)::

    evaluate --contacts bags/generated/icub_contacts --json results/contacts.json \
        --plot results/contacts.png

Argument parsing only; the work is done by :mod:`semiparam_ros.eval`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import yaml

from semiparam_ros.cli.errors import error_exit

__all__ = ["add_config_arguments", "build_parser", "main", "parse_overrides"]


def parse_overrides(items: Sequence[str]) -> dict[str, object]:
    """Parse ``name=value`` overrides (values in YAML syntax: ``0.1``, ``true``, ``[a, b]``).

    Args:
        items: Strings ``dotted.name=value``.

    Returns:
        Dotted names to parsed values.

    Raises:
        ValueError: On an item without ``=``.
    """
    out: dict[str, object] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--set expects name=value, got {item!r}")
        out[name.strip()] = yaml.safe_load(value)
    return out


def add_config_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options every bag-replaying command shares: ``--config``, ``--set`` and the input topics.

    Args:
        p: The parser to extend (``evaluate``'s or ``tune``'s).
    """
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="ROS 2 parameter file (default: the shipped config/icub_right_arm.yaml)",
    )
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a parameter, e.g. --set nonparametric.n_features=200 (repeatable)",
    )
    p.add_argument("--joint-states-topic", help="JointState topic (default: /<topics.joint_states>)")
    p.add_argument("--wrench-topic", help="WrenchStamped topic (default: /<topics.wrench>)")


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``evaluate``."""
    p = argparse.ArgumentParser(
        prog="evaluate",
        description="Replay bags through the estimator's pipeline and learners: the paper's protocol "
        "(--train/--test) or the payload adaptation scenario (--payload).",
    )
    p.add_argument(
        "--train",
        type=Path,
        help="training bag (paper: the XY circles); with --payload: "
        "optional bag every learner is trained on first",
    )
    p.add_argument("--test", type=Path, help="test bag (paper: the XZ circles)")
    p.add_argument("--payload", type=Path, help="bag with a payload pickup (adaptation scenario)")
    p.add_argument("--contacts", type=Path,
                   help="bag with contact episodes in its scenario.yaml (simulate --scenario contacts): the "
                   "estimator with the contact gate on and off")
    add_config_arguments(p)
    p.add_argument(
        "--models",
        nargs="+",
        choices=("P", "NP", "SP", "SPJ", "SPC", "SPfrozenP"),
        default=None,
        help="learners (default: P NP SP; with --payload: SP); SP = semiparametric.combination as "
        "configured (default 'consistent'); SPJ = the joint semiparametric fit "
        "(semiparametric.combination=joint whatever the configuration says; needs equal "
        "forgetting factors); SPC = the paper's cascade whatever the configuration says; SPfrozenP = "
        "diagnostic cascade whose rigid-body stage stops learning after the training bag",
    )
    p.add_argument("--splits", type=int, default=10, help="number of sequential test parts (default 10)")
    p.add_argument(
        "--split-size",
        type=int,
        default=None,
        help="samples per part (paper: 1000); omitted: the test bag in --splits equal parts",
    )
    p.add_argument("--window", type=float, default=3.0, help="sliding RMSE window [s] (default 3)")
    p.add_argument(
        "--first",
        type=float,
        default=3.0,
        help="initial segment of each part reported separately [s] (default 3: *_first_3s)",
    )
    p.add_argument("--train-limit", type=int, default=None, help="use only the first N training samples")
    p.add_argument("--test-limit", type=int, default=None, help="use only the first N test samples")
    p.add_argument(
        "--test-skip",
        type=int,
        default=0,
        help="drop the first N test samples (with --train-limit N on the same bag: the protocol "
        "within one bag, e.g. for hyperparameter selection on training data)",
    )
    p.add_argument(
        "--pickup-time",
        type=float,
        default=None,
        help="payload pickup [s from the bag's first joint state]; default from the bag's scenario.yaml",
    )
    p.add_argument(
        "--forgetting",
        type=float,
        default=0.995,
        help="forgetting factor per sample with adaptation on (default 0.995)",
    )
    p.add_argument(
        "--forgetting-np",
        type=float,
        default=None,
        help="forgetting factor of the residual stage with adaptation on (default: --forgetting)",
    )
    p.add_argument("--json", type=Path, help="write the JSON report here")
    p.add_argument("--plot", type=Path, help="write the figure (PNG) here")
    p.add_argument(
        "--plot-truth",
        type=Path,
        help="also plot the errors against the noise-free wrench (simulated bags) here",
    )
    p.add_argument("--markdown", type=Path, help="write the markdown table here")
    p.add_argument(
        "--horizons", nargs="*", default=None, metavar="SECONDS",
        help="paper protocol: also score each model by its age h (learned up to t - h, predicts t) beside "
             "persistence held h and the CAD model; seconds, 0 = one step, 'frozen' (given without "
             "values: 0 0.1 1 10 frozen)",
    )
    p.add_argument("--horizon-plot", type=Path, help="write the error-by-age figure (PNG) here")
    p.add_argument("--per-sample", type=Path, metavar="FILE.csv",
                   help="paper protocol: write every test sample (stamp, measured, each model's prediction "
                        "and std per component) as CSV here")
    p.add_argument("--per-sample-plot", type=Path, metavar="FILE.png",
                   help="paper protocol: measured vs each model's prediction over time, one panel per "
                        "joint/axis")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (one is drawn only when stderr is a terminal anyway)",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``evaluate`` console script.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        Exit status: 0 on success, 2 on invalid input, 1 if a file cannot be read or written.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.contacts is not None and (args.payload is not None or args.test is not None):
        parser.error("--contacts is exclusive with --payload and --test")
    if args.contacts is None and args.payload is None and (args.train is None or args.test is None):
        parser.error("give --train and --test (paper protocol), --payload (adaptation scenario) or "
                     "--contacts (contact evaluation)")
    if args.payload is not None and args.test is not None:
        parser.error("--payload and --test are exclusive")
    if (args.per_sample or args.per_sample_plot) and args.test is None:
        parser.error("--per-sample and --per-sample-plot go with the paper protocol (--train and --test)")
    from semiparam_ros.eval.horizon import DEFAULT_HORIZONS  # heavy imports after argument checks
    from semiparam_ros.eval.run import run_evaluate

    try:
        text = run_evaluate(
            train=args.train,
            test=args.test,
            payload=args.payload,
            contacts=args.contacts,
            config=args.config,
            overrides=parse_overrides(args.overrides),
            joint_states_topic=args.joint_states_topic,
            wrench_topic=args.wrench_topic,
            models=args.models,
            splits=args.splits,
            split_size=args.split_size,
            window_s=args.window,
            first_s=args.first,
            train_limit=args.train_limit,
            test_limit=args.test_limit,
            test_skip=args.test_skip,
            pickup_time_s=args.pickup_time,
            forgetting=args.forgetting,
            forgetting_nonparametric=args.forgetting_np,
            json_path=args.json,
            plot_path=args.plot,
            plot_truth_path=args.plot_truth,
            markdown_path=args.markdown,
            horizons=None if args.horizons is None else (args.horizons or DEFAULT_HORIZONS),
            horizon_plot_path=args.horizon_plot,
            per_sample_path=args.per_sample,
            per_sample_plot_path=args.per_sample_plot,
            progress=not args.no_progress,
        )
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("evaluate", err)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
