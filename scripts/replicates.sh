#!/usr/bin/env bash
# Replicate the paper's protocol over independently simulated logs: for each simulator seed, generate the
# paper-preset XY and XZ bags (new sensor noise and a new wander of the hand's speed, circle centre and
# radius; robot, non-rigid effects, hyperparameters and protocol unchanged), run `evaluate` with P, NP, SP
# and SPJ at the hyperparameters of scripts/reproduce.sh, and summarize over seeds: how often each of the
# issue's criteria holds, and paired comparisons over seeds (semiparam_ros/eval/replicates.py).
#
#   bash scripts/replicates.sh                      # seeds 1..10 → docs/figures/replicates.json
#   bash scripts/replicates.sh --seeds "1 2 3" --out DIR --jobs 2
#
# About 1 min per seed and core; --jobs seeds run at a time (default -1: all cores). Seed 0 is the headline
# run of reproduce.sh and is not repeated here. The per-seed bags live in temporary folders and are removed.
# Then `bash scripts/reproduce.sh` (or only its last step) adds the summary to the results page.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
seeds="1 2 3 4 5 6 7 8 9 10"
out=docs
jobs=-1
while [ $# -gt 0 ]; do
  case "$1" in
    --seeds) seeds=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    *) echo "usage: $0 [--seeds \"S1 S2 ...\"] [--out DIR] [--jobs N]" >&2; exit 2 ;;
  esac
done
source scripts/paper_params.sh
# this page reproduces the paper's learner, the cascade, whatever the package default (docs/generalization.md)
tuned+=(--set semiparametric.combination=cascade)
# one job per seed (simulate the two logs, run the protocol, keep the scalars), on every core through
# joblib (semiparam_ros/jobs/parallel.py); each job has one BLAS thread, so the numbers do not depend on --jobs
.venv/bin/python - "$config" "$out/figures/replicates.json" "$jobs" $seeds "--" "${tuned[@]}" <<'PY'
import sys
import tempfile
from pathlib import Path

from semiparam_ros.cli.evaluate import parse_overrides
from semiparam_ros.cli.simulate import main as simulate
from semiparam_ros.jobs.parallel import run_jobs
from semiparam_ros.eval.bags.replay import evaluate_bags
from docs.tools.replicates import replicate_summary, replicates_markdown
from semiparam_ros.eval.protocol.report import protocol_report, write_json
from semiparam_ros.report.evaluation import load_evaluation_config

config_path, out, jobs = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3])
rest = sys.argv[4:]
cut = rest.index("--")
seeds = [int(s) for s in rest[:cut]]
overrides = parse_overrides([v for v in rest[cut + 1:] if v != "--set"])


def one_seed(seed: int):
    cfg = load_evaluation_config(config_path, overrides)
    with tempfile.TemporaryDirectory() as work:
        if simulate(["--preset", "paper", "--seed", str(seed), "--out", work, "--scenario", "xy",
                     "--scenario", "xz", "--quiet"]) != 0:
            raise RuntimeError(f"simulate failed for seed {seed}")
        result, info = evaluate_bags(Path(work, "icub_xy"), Path(work, "icub_xz"), cfg,
                                     kinds=("P", "NP", "SP", "SPJ"), splits=10, split_size=1000, window_s=3.0)
    print(f"seed {seed} done", flush=True)
    return protocol_report(result, config=cfg.to_flat(), protocol=info)


summary = replicate_summary(run_jobs(one_seed, [(s,) for s in seeds], jobs=jobs), seeds)
write_json(summary, out)
print(replicates_markdown(summary))
print(f"wrote {out}")
PY
