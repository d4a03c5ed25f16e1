#!/usr/bin/env bash
# Regenerate the figures the guides show (docs/figures/):
#   real_robots_served_1to3.png, real_robots_horizons_1to3.png, real_robots_13.json — the served model on
#     the real KUKA LWR4+ logs (train log 1, test log 3: new motion), needs ../shared/data/kuka_lwr4;
#   identification_kuka.png — excite → simulate → learn → export_urdf on the KUKA's URDF, with a payload on
#     the hand, before and after against the simulator's truth on other motion.
# About 3 min.   bash scripts/docs_figures.sh [DATA_FOLDER]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
data=${1:-$root/../shared/data/kuka_lwr4}
cd "$root"
bash scripts/setup.sh
export PYTHONPATH="$root${PYTHONPATH:+:$PYTHONPATH}"
.venv/bin/real_robots --data "$data" --json docs/figures/real_robots_13.json \
  --figure docs/figures/real_robots_horizons_1to3.png --served-figure docs/figures/real_robots_served_1to3.png \
  --no-progress > /dev/null
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
urdf="$data/kuka_lwr4_cogimon.urdf"
joints="lwr_0_joint lwr_1_joint lwr_2_joint lwr_3_joint lwr_4_joint lwr_5_joint lwr_6_joint"
.venv/bin/excite --config config/kuka_lwr4.yaml --set robot.urdf="$urdf" --duration 20 --out "$work/traj.mcap" > /dev/null
# shellcheck disable=SC2086
.venv/bin/simulate --urdf "$urdf" --joints $joints --trajectory "$work/traj.excitation.yaml" --scenario payload \
  --payload-time 0 --duration 20 --out "$work/train" --quiet > /dev/null
# shellcheck disable=SC2086
.venv/bin/simulate --urdf "$urdf" --joints $joints --scenario payload --payload-time 0 --duration 20 \
  --rate 500 --out "$work/test" --quiet > /dev/null
bag="$work/train/kuka_lwr_payload_1000hz"
.venv/bin/learn "$bag" --config "$bag/params.yaml" --checkpoint "$work/ident.npz" --quiet > /dev/null
.venv/bin/export_urdf --checkpoint "$work/ident.npz" --out "$work/identified.urdf" > /dev/null
.venv/bin/python -m docs.tools.identification_figure "$bag" "$work/test/kuka_lwr_payload_500hz" \
  "$work/identified.urdf" docs/figures/identification_kuka.png
echo "wrote docs/figures/real_robots_served_1to3.png, real_robots_horizons_1to3.png, real_robots_13.json, identification_kuka.png"
