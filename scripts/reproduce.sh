#!/usr/bin/env bash
# Reproduce the paper's experiment (Camoriano et al., ICRA 2016, Fig. 3) and the payload-adaptation
# result on the synthetic iCub bags, and regenerate the results page with its figures.
#
#   bash scripts/reproduce.sh              # writes docs/results.md and docs/figures/*
#   bash scripts/reproduce.sh --out DIR    # writes DIR/results.md and DIR/figures/* instead
#   bash scripts/reproduce.sh --jobs 1     # grid points one at a time (default -1: all cores; same numbers)
#
# Steps: (1) generate the paper-preset bags (XY and XZ circles, wrench at 10 Hz, 10 000 samples each)
# with the simulator if bags/generated/ does not hold them yet; (2) `evaluate` on them: P, NP, SP (the
# paper's cascade) and SPJ (the joint semiparametric fit, core/learners/joint.py) from zero, trained
# on all of XY, test-then-train on 10 sequential parts of XZ; (3) `evaluate payload` on the committed
# payload bag: SP and SPJ with and without forgetting around the pickup; (4) the results page, the words of
# docs/templates/results.md.in filled with the numbers of the JSON reports (semiparam_ros/eval/pages.py).
# Hyperparameter selection on the training bag goes through `tune` (semiparam_ros/tune/selection.py), whose
# grid points run in parallel with joblib. Deterministic: the simulator and the random features are seeded.
# Takes about 10 minutes on 2 cores.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
out=docs
jobs=-1
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    *) echo "usage: $0 [--out DIR] [--jobs N]" >&2; exit 2 ;;
  esac
done
bin=.venv/bin
source scripts/paper_params.sh  # config, tuned (the hyperparameters used below)
# this page reproduces the paper's learner, the cascade, whatever the package default (docs/generalization.md)
tuned+=(--set semiparametric.combination=cascade)
gen=bags/generated
figs="$out/figures"
mkdir -p "$figs"

# (re)generate when missing or written by an older simulator (no trajectory variability / lead-in)
if ! grep -q lead_in_s "$gen/icub_xy/scenario.yaml" 2>/dev/null \
   || ! grep -q lead_in_s "$gen/icub_xz/scenario.yaml" 2>/dev/null; then
  echo "== generating the paper-preset bags in $gen (simulate --preset paper)"
  "$bin/simulate" --preset paper --out "$gen" --scenario xy --scenario xz --overwrite
fi

# Hyperparameters selected on the TRAINING bag only (docs/results.md): `tune` on the XY bag (hold-out =
# its last 20 %, run below) and the paper's protocol run within the XY bag (train on its first half,
# test-then-train on 5 parts of its second half) both select λ_P = 0.01, λ_NP = 0.001, σ = 6 for D = 500.
# The test bag (XZ) played no part in the choice. The selection is for the cascade SP; SPJ runs with the
# same values (not selected separately).

echo "== selection on the training bag: the protocol within XY (train on its first 5000 samples, test-then-train"
echo "   on 5 parts of 1000 of the rest), grid λ_NP × σ (λ_P = 0.01: insensitive, see tune below); SP selects"
echo "   the values used; NP and SPJ, scored on the same runs, get their own selection in a second run below"
"$bin/tune" --train "$gen/icub_xy" --config "$config" "${tuned[@]}" --method protocol --models NP SP SPJ \
  --lam-np 0.001 0.01 0.1 --sigma 3 4 6 8 --train-n 5000 --splits 5 --split-size 1000 --window 3.0 \
  --jobs "$jobs" --json "$figs/select_xy.json" --no-progress > /dev/null

echo "== the protocol within XY at the values used: P, NP, SP, SPJ (cascade vs joint in distribution)"
"$bin/evaluate" paper --train "$gen/icub_xy" --test "$gen/icub_xy" --config "$config" "${tuned[@]}" \
  --models P NP SP SPJ --train-limit 5000 --test-skip 5000 --splits 5 --split-size 1000 --window 3.0 \
  --json "$figs/within_xy.json" --no-progress > /dev/null

# 10 sequential parts of exactly 1000 samples (the simulator starts the joint states 0.2 s before the
# first wrench, so all 10 000 wrenches become samples)
echo "== paper protocol: train on XY, test-then-train on 10 sequential parts of XZ"
"$bin/evaluate" paper --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --models P NP SP SPJ --splits 10 --split-size 1000 --window 3.0 \
  --json "$figs/paper.json" --plot "$figs/paper_fig3.png" --plot-truth "$figs/paper_fig3_noise_free.png"

echo "== each learner with the values selected for it on the within-XY runs (same protocol, same parts)"
while read -r kind lnp sigma; do
  "$bin/evaluate" paper --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
    --set nonparametric.lam="$lnp" --set nonparametric.sigma="$sigma" --models "$kind" \
    --splits 10 --split-size 1000 --window 3.0 --json "$figs/own_$kind.json" --no-progress > /dev/null
done < <("$bin/python" -c '
import json, sys
doc = json.load(open(sys.argv[1]))
for kind, sel in doc["selections"].items():
    print(kind, repr(sel["best"]["nonparametric.lam"]), repr(sel["best"]["nonparametric.sigma"]))
' "$figs/select_xy.json")

echo "== diagnostic: SP with its rigid-body stage frozen after training (isolates the drift of that stage)"
"$bin/evaluate" paper --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --splits 10 --split-size 1000 --window 3.0 --models NP SP SPfrozenP --json "$figs/diagnostic_frozen_p.json" --no-progress \
  > /dev/null

echo "== sensitivity (diagnostic, not a selection): λ_NP = 0.01, σ = 4, the values an earlier sweep picked on the test log"
"$bin/evaluate" paper --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --set nonparametric.lam=0.01 --set nonparametric.sigma=4.0 \
  --splits 10 --split-size 1000 --window 3.0 --json "$figs/sensitivity.json" --no-progress > /dev/null

echo "== payload scenario: SP and SPJ with and without adaptation around the pickup"
"$bin/evaluate" payload bags/icub_payload --config "$config" "${tuned[@]}" --forgetting 0.995 \
  --models SP SPJ --json "$figs/payload.json" --plot "$figs/payload.png"

echo "== hold-out selection on the XY bag alone (tune), for comparison with the values used above"
"$bin/tune" --train "$gen/icub_xy" --config "$config" --n-features 500 --holdout 0.2 \
  --lam-p 0.01 0.1 1 --lam-np 0.001 0.01 0.1 1 --sigma 2 3 4 6 --jobs "$jobs" --json "$figs/tune_xy.json" \
  --no-progress > /dev/null

echo "== results page (words: docs/templates/results.md.in; numbers: the JSON reports above)"
"$bin/python" -c '
import sys
from docs.tools.pages import write_results
write_results(sys.argv[1], sys.argv[2], sys.argv[3], command=sys.argv[4])
' "$figs" "$out/results.md" docs/templates/results.md.in "bash scripts/reproduce.sh$([ "$out" = docs ] || echo " --out $out")"
echo "wrote $out/results.md"
