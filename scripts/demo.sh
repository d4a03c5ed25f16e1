#!/usr/bin/env bash
# The main job in a few minutes: set up (idempotent), generate the synthetic iCub bags of the paper's
# experiment (deterministic; reused when present), replay them through the estimator's core with the
# paper's protocol (P, NP and SP learners), print the RMSE table and write the report and the figure to
# results/. The full paper-scale reproduction (selection grids, diagnostics, payload scenario, results
# page) is its own command: `bash scripts/reproduce.sh` (docs/results.md).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
bash scripts/setup.sh
source scripts/paper_params.sh  # config, tuned (the hyperparameters selected on the training bag)
gen=bags/generated
if ! grep -q lead_in_s "$gen/icub_xy/scenario.yaml" 2>/dev/null \
   || ! grep -q lead_in_s "$gen/icub_xz/scenario.yaml" 2>/dev/null; then
  echo "== generating the paper-preset bags in $gen (simulate --preset paper, about 1 min)"
  .venv/bin/simulate --preset paper --out "$gen" --scenario xy --scenario xz --overwrite --quiet
fi
echo "== paper protocol: train P, NP, SP on XY, test-then-train on 10 parts of XZ (about 1 min)"
.venv/bin/evaluate paper --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --models P NP SP --splits 10 --split-size 1000 --window 3.0 \
  --json results/paper.json --plot results/paper_fig3.png --markdown results/paper.md "$@"
echo "wrote results/paper.json, results/paper_fig3.png, results/paper.md"
