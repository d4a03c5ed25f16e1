#!/usr/bin/env bash
# Replicate the paper's protocol over independently simulated logs: for each simulator seed, generate the
# paper-preset XY and XZ bags (new sensor noise and a new wander of the hand's speed, circle centre and
# radius; robot, non-rigid effects, hyperparameters and protocol unchanged), run `evaluate` with P, NP, SP
# and SPJ at the hyperparameters of scripts/reproduce.sh, and summarize over seeds: how often each of the
# issue's criteria holds, and paired comparisons over seeds (semiparam_ros/eval/replicates.py).
#
#   bash scripts/replicates.sh                      # seeds 1..10 → docs/figures/replicates.json
#   bash scripts/replicates.sh --seeds "1 2 3" --out DIR
#
# About 1 min per seed and core; two seeds run at a time. Seed 0 is the headline run of reproduce.sh and
# is not repeated here. The per-seed bags and reports live in a temporary folder and are removed.
# Then `bash scripts/reproduce.sh` (or only its last step) adds the summary to the results page.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
seeds="1 2 3 4 5 6 7 8 9 10"
out=docs
while [ $# -gt 0 ]; do
  case "$1" in
    --seeds) seeds=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    *) echo "usage: $0 [--seeds \"S1 S2 ...\"] [--out DIR]" >&2; exit 2 ;;
  esac
done
source scripts/paper_params.sh
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export work config
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
one_seed() {
  local s=$1
  .venv/bin/simulate --preset paper --seed "$s" --out "$work/s$s" --scenario xy --scenario xz --quiet > /dev/null
  # shellcheck disable=SC2086
  .venv/bin/evaluate --train "$work/s$s/icub_xy" --test "$work/s$s/icub_xz" --config "$config" \
    $tuned_str --models P NP SP SPJ --splits 10 --split-size 1000 --window 3.0 \
    --json "$work/seed_$s.json" --no-progress > /dev/null
  rm -rf "${work:?}/s$s"
  echo "seed $s done"
}
export tuned_str="${tuned[*]}"  # words without spaces: split again inside one_seed
export -f one_seed
printf '%s\n' $seeds | xargs -P 2 -I{} bash -c 'one_seed {}'
.venv/bin/python -c '
import json, sys
from pathlib import Path
from semiparam_ros.eval.replicates import replicate_summary, replicates_markdown
from semiparam_ros.eval.report import write_json
work, out = Path(sys.argv[1]), Path(sys.argv[2])
seeds = [int(s) for s in sys.argv[3:]]
summary = replicate_summary([json.loads((work / f"seed_{s}.json").read_text()) for s in seeds], seeds)
write_json(summary, out)
print(replicates_markdown(summary))
' "$work" "$out/figures/replicates.json" $seeds
echo "wrote $out/figures/replicates.json"
