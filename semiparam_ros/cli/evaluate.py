"""``evaluate``: replay bags through the estimator's core; one subcommand per evaluation.

Paper protocol (P, NP, SP from zero; train on all of TRAIN; test-then-train on --splits parts of TEST)::

    evaluate paper --train bags/generated/icub_xy --test bags/generated/icub_xz --split-size 1000 \
        --json results/report.json --plot results/fig3.png

Add ``--models P NP SP SPJ SPC`` to compare the default (consistent) SP with the joint semiparametric fit
(``SPJ``) and the paper's cascade (``SPC``).

Payload scenario (one bag with a pickup; SP with and without forgetting)::

    evaluate payload bags/icub_payload --forgetting 0.995 --json results/payload.json \
        --plot results/payload.png

Contact evaluation (a ``simulate --scenario contacts`` log: the node's estimator with the gate on and off;
contact detection per episode, the error after the contacts vs before, payload adoption)::

    evaluate contacts bags/generated/icub_contacts --json results/contacts.json --plot results/contacts.png

Argument parsing only; the work is done by :mod:`semiparam_ros.report.evaluation`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import yaml

from semiparam_ros.cli.exit_codes import error_exit

__all__ = ["add_config_arguments", "build_parser", "main", "parse_overrides"]


def parse_overrides(items: Sequence[str], option: str = "--set") -> dict[str, object]:
    """Parse ``name=value`` overrides (values in YAML syntax: ``0.1``, ``true``, ``[a, b]``).

    Args:
        items: Strings ``dotted.name=value``.
        option: The command-line option they came from (named in the error).

    Returns:
        Dotted names to parsed values.

    Raises:
        ValueError: On an item without ``=``.
    """
    out: dict[str, object] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"{option} expects name=value, got {item!r}")
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


_MODELS = ("P", "NP", "SP", "SPJ", "SPC", "SPfrozenP")


def _add_common(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p)
    p.add_argument("--json", type=Path, help="write the JSON report here")
    p.add_argument("--plot", type=Path, help="write the figure (PNG) here")
    p.add_argument("--markdown", type=Path, help="write the markdown tables here")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress bar (one is drawn only when stderr is a terminal anyway)")


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``evaluate`` (subcommands ``paper``, ``payload``, ``contacts``)."""
    from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S, DEFAULT_SPLITS, DEFAULT_WINDOW_S

    parser = argparse.ArgumentParser(prog="evaluate", description="Replay bags through the estimator's "
                                     "pipeline and learners.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{paper,payload,contacts}")
    p = sub.add_parser("paper", help="the paper's protocol: train on one bag, test-then-train on parts of "
                       "another")
    p.add_argument("--train", type=Path, required=True, help="training bag (paper: the XY circles)")
    p.add_argument("--test", type=Path, required=True, help="test bag (paper: the XZ circles)")
    _add_common(p)
    p.add_argument("--models", nargs="+", choices=_MODELS, default=None,
                   help="learners (default: P NP SP); SP = semiparametric.combination as configured "
                   "(default 'consistent'); SPJ = the joint semiparametric fit (needs equal forgetting "
                   "factors); SPC = the paper's cascade; SPfrozenP = diagnostic cascade whose rigid-body "
                   "stage stops learning after the training bag")
    p.add_argument("--splits", type=int, default=DEFAULT_SPLITS,
                   help="sequential test parts (default %(default)s)")
    p.add_argument("--split-size", type=int, default=None,
                   help="samples per part (paper: 1000); omitted: the test bag in --splits equal parts")
    p.add_argument("--window", type=float, default=DEFAULT_WINDOW_S,
                   help="sliding RMSE window [s] (default %(default)s)")
    p.add_argument("--first", type=float, default=DEFAULT_FIRST_S,
                   help="initial segment of each part reported separately [s] (default %(default)s)")
    p.add_argument("--train-limit", type=int, default=None, help="use only the first N training samples")
    p.add_argument("--test-limit", type=int, default=None, help="use only the first N test samples")
    p.add_argument("--test-skip", type=int, default=0,
                   help="drop the first N test samples (with --train-limit N on the same bag: the protocol "
                   "within one bag, e.g. for hyperparameter selection on training data)")
    p.add_argument("--plot-truth", type=Path,
                   help="also plot the errors against the noise-free outputs (simulated bags) here")
    p.add_argument("--horizons", nargs="*", default=None, metavar="SECONDS",
                   help="also score each model by its age h (learned up to t - h, predicts t) beside "
                   "persistence held h and the CAD model; seconds, 0 = one step, 'frozen' (given without "
                   "values: 0 0.1 1 10 frozen)")
    p.add_argument("--horizon-plot", type=Path, help="write the error-by-age figure (PNG) here")
    p.add_argument("--per-sample", type=Path, metavar="FILE.csv",
                   help="write every test sample (stamp, measured, each model's prediction and std per "
                   "component) as CSV here")
    p.add_argument("--per-sample-plot", type=Path, metavar="FILE.png",
                   help="measured vs each model's prediction over time, one panel per joint/axis")
    p.add_argument("--jobs", type=int, default=1,
                   help="models run in parallel on this machine (default 1; -1: all cores); same numbers")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="run one job per model on a Dask cluster: a scheduler address (tcp://host:8786) or "
                        "local:N (same numbers as the serial run; docs/scale.md)")
    p = sub.add_parser("payload", help="the payload scenario: each learner with and without forgetting")
    p.add_argument("bag", type=Path, help="bag with a payload pickup")
    p.add_argument("--train", type=Path, help="optional bag every learner is trained on first")
    _add_common(p)
    p.add_argument("--models", nargs="+", choices=_MODELS, default=None, help="learners (default: SP)")
    p.add_argument("--window", type=float, default=DEFAULT_WINDOW_S,
                   help="sliding RMSE window [s] (default %(default)s)")
    p.add_argument("--pickup-time", type=float, default=None,
                   help="payload pickup [s from the bag's first joint state]; default from its scenario.yaml")
    p.add_argument("--forgetting", type=float, default=0.995,
                   help="forgetting factor per sample with adaptation on (default %(default)s)")
    p.add_argument("--forgetting-np", type=float, default=None,
                   help="forgetting factor of the residual stage with adaptation on (default: --forgetting)")
    p = sub.add_parser("contacts", help="contact detection on a log with contact episodes, gate on and off")
    p.add_argument("bag", type=Path, help="bag whose scenario.yaml lists contact episodes")
    _add_common(p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``evaluate`` console script.

    Args:
        argv: Arguments (default: ``sys.argv[1:]``).

    Returns:
        Exit status: 0 on success, 2 on invalid input, 1 if a file cannot be read or written.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    from semiparam_ros.core.config import load_evaluation_config
    from semiparam_ros.eval.bags.replay import Topics
    from semiparam_ros.eval.protocol.horizon import DEFAULT_HORIZONS  # heavy imports after argument checks
    from semiparam_ros.eval.protocol.options import ProtocolOptions
    from semiparam_ros.report.evaluation import (
        ReportPaths,
        evaluate_contacts,
        evaluate_paper,
        evaluate_payload,
    )

    try:
        cfg = load_evaluation_config(args.config, parse_overrides(args.overrides))
        topics = Topics.from_config(cfg, args.joint_states_topic, args.wrench_topic)
        paths = ReportPaths(json=args.json, markdown=args.markdown, plot=args.plot)
        progress = not args.no_progress
        if args.command == "contacts":
            text = evaluate_contacts(args.bag, cfg, topics=topics, paths=paths)
        elif args.command == "payload":
            text = evaluate_payload(args.bag, cfg, topics=topics, models=args.models,
                                    forgetting=args.forgetting, forgetting_nonparametric=args.forgetting_np,
                                    pickup_time_s=args.pickup_time, pretrain=args.train, window_s=args.window,
                                    paths=paths, progress=progress)
        else:
            options = ProtocolOptions(splits=args.splits, split_size=args.split_size, window_s=args.window,
                                      first_s=args.first, train_limit=args.train_limit,
                                      test_limit=args.test_limit, test_skip=args.test_skip)
            paths = ReportPaths(json=args.json, markdown=args.markdown, plot=args.plot,
                                plot_truth=args.plot_truth, horizon_plot=args.horizon_plot,
                                per_sample=args.per_sample, per_sample_plot=args.per_sample_plot)
            horizons = None if args.horizons is None else (args.horizons or DEFAULT_HORIZONS)
            text = evaluate_paper(args.train, args.test, cfg, topics=topics, models=args.models,
                                  options=options, horizons=horizons, paths=paths, progress=progress,
                                  jobs=args.jobs, cluster=args.cluster)
    except (ValueError, OSError) as err:  # e.g. a bad value or an output folder that cannot be created
        return error_exit("evaluate", err)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
