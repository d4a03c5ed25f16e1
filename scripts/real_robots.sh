#!/usr/bin/env bash
# P, NP and SP on the real KUKA LWR4+ joint-torque logs: train on measurements_1, test
# on measurements_3 with the project's protocol (10 parts, "at regime" = second half of each part), beside
# the CAD model, batch least-squares identification with friction (frozen and updated online), each learner
# frozen after training, P without friction, and persistence; plus the injected external-torque test.
# Writes results/real_robots.{json,md} and prints the tables (docs/real_robots.md discusses them).
#
#   bash scripts/real_robots.sh [DATA_FOLDER] [more real_robots options, e.g. --splits 1 --test measurements_2]
#
# DATA_FOLDER defaults to ../shared/data/kuka_lwr4 beside the repository (not shipped: LGPL-3.0 logs of
# FloBaRoID, see that folder's README.md and LICENSE_LGPLv3.md). About 30 s.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=${1:-$root/../shared/data/kuka_lwr4}
shift || true
cd "$root"
mkdir -p results
PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}" .venv/bin/python -m semiparam_ros.cli.real_robots \
  --data "$data" --json results/real_robots.json --markdown results/real_robots.md --figure results/real_robots_horizons.png \
  --served-figure results/real_robots_served.png --no-progress "$@"
