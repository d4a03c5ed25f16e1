#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the embedded default: generate the synthetic iCub bags of the
# paper's experiment (deterministic), replay them through the estimator's core (P, NP and SP learners),
# print the RMSE table and write the figures to results/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
bash scripts/setup.sh
exec bash scripts/reproduce.sh --out results "$@"
