#!/usr/bin/env bash
# Reproduce the paper's experiment (Camoriano et al., ICRA 2016, Fig. 3) and the payload-adaptation
# result on the synthetic iCub bags, and regenerate the results page with its figures.
#
#   bash scripts/reproduce.sh              # writes docs/results.md and docs/figures/*
#   bash scripts/reproduce.sh --out DIR    # writes DIR/results.md and DIR/figures/* instead
#
# Steps: (1) generate the paper-preset bags (XY and XZ circles, wrench at 10 Hz, 10 000 samples each)
# with the simulator if bags/generated/ does not hold them yet; (2) `evaluate` on them: P, NP, SP from
# zero, trained on all of XY, test-then-train on 10 sequential parts of XZ; (3) `evaluate --payload`
# on the committed payload bag: SP with and without forgetting around the pickup; (4) the results page.
# Deterministic: the simulator and the random features are seeded. Takes a few minutes on 2 cores.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
out=docs
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    *) echo "usage: $0 [--out DIR]" >&2; exit 2 ;;
  esac
done
bin=.venv/bin
config=config/icub_right_arm.yaml
gen=bags/generated
figs="$out/figures"
mkdir -p "$figs"

if [ ! -f "$gen/icub_xy/metadata.yaml" ] || [ ! -f "$gen/icub_xz/metadata.yaml" ]; then
  echo "== generating the paper-preset bags in $gen (simulate --preset paper)"
  "$bin/simulate" --preset paper --out "$gen"
fi

# Hyperparameters selected for this reproduction (docs/results.md); the same values are proposed for
# config/icub_right_arm.yaml, after which these overrides are no-ops.
tuned=(--set parametric.lam=0.01 --set nonparametric.lam=0.01 --set nonparametric.sigma=4.0
       --set nonparametric.n_features=500)

# 10 equal parts of the XZ samples (1000 each when the pipeline yields 10 000; the first wrench of a bag
# can fall in the acceleration estimator's warm-up, leaving 9 999 → parts of 999)
echo "== paper protocol: train on XY, test-then-train on 10 sequential parts of XZ"
"$bin/evaluate" --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --splits 10 --window 3.0 \
  --json "$figs/paper.json" --plot "$figs/paper_fig3.png" --plot-truth "$figs/paper_fig3_noise_free.png"

echo "== diagnostic: SP with its rigid-body stage frozen after training (isolates the drift of that stage)"
"$bin/evaluate" --train "$gen/icub_xy" --test "$gen/icub_xz" --config "$config" "${tuned[@]}" \
  --splits 10 --window 3.0 --models NP SP SPfrozenP --json "$figs/diagnostic_frozen_p.json" --no-progress \
  > /dev/null

echo "== payload scenario: SP with and without adaptation around the pickup"
"$bin/evaluate" --payload bags/icub_payload --config "$config" "${tuned[@]}" --forgetting 0.995 \
  --json "$figs/payload.json" --plot "$figs/payload.png"

echo "== hold-out selection on the XY bag alone (tune), for comparison with the values used above"
"$bin/tune" --train "$gen/icub_xy" --config "$config" --n-features 500 --holdout 0.2 \
  --lam-p 0.01 1 --lam-np 0.01 0.1 1 --sigma 2 3 4 --json "$figs/tune_xy.json" --no-progress > /dev/null

echo "== results page"
"$bin/python" -c '
import sys
from semiparam_ros.eval.results import write_results
write_results(sys.argv[1], sys.argv[2], sys.argv[3], command=sys.argv[4])
' "$figs/paper.json" "$figs/payload.json" "$out/results.md" "bash scripts/reproduce.sh$([ "$out" = docs ] || echo " --out $out")"
echo "wrote $out/results.md"
