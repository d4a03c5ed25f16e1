#!/usr/bin/env bash
# Contact evaluation: simulate contacts-then-pickup logs (iCub F/T sensor, seeds 0..3;
# Panda joint torques at 100 Hz, seed 0), run `evaluate contacts` on each with the shipped
# configuration (gate on and off in one run), and fill docs/templates/contacts.md.in with the numbers
# (semiparam_ros/eval/contacts_page.py).
#
#   bash scripts/contacts.sh                  # writes docs/contacts.md and docs/figures/contacts*
#   bash scripts/contacts.sh --out DIR        # writes DIR/contacts.md and DIR/figures/contacts* instead
#   bash scripts/contacts.sh --seeds "0 1"    # iCub seeds (the first is the headline log)
#
# The bags live in a temporary folder and are removed. About 2.5 min per log on one core.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
out=docs
seeds="0 1 2 3"
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --seeds) seeds=$2; shift 2 ;;
    *) echo "usage: $0 [--out DIR] [--seeds \"S1 S2 ...\"]" >&2; exit 2 ;;
  esac
done
py=.venv/bin/python
export OPENBLAS_NUM_THREADS=1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$out/figures"
rm -f "$out"/figures/contacts_*.json
first=1
for s in $seeds; do
  "$py" -m semiparam_ros.cli.simulate --out "$tmp/icub$s" --scenario contacts --seed "$s" --quiet
  plot=()
  if [ "$first" = 1 ]; then plot=(--plot "$out/figures/contacts.png"); first=0; fi
  "$py" -m semiparam_ros.cli.evaluate contacts "$tmp/icub$s/icub_contacts" --no-progress \
    --json "$out/figures/contacts_icub_seed$s.json" "${plot[@]}"
done
"$py" -m semiparam_ros.cli.simulate --out "$tmp/panda" --robot panda --rate 100 --scenario contacts --quiet
"$py" -m semiparam_ros.cli.evaluate contacts "$tmp/panda/panda_contacts_100hz" --config config/panda.yaml \
  --no-progress --json "$out/figures/contacts_panda.json" --plot "$out/figures/contacts_panda.png"
"$py" - "$out/figures" "$out/contacts.md" docs/templates/contacts.md.in <<'PY'
import sys

from docs.tools.contacts_page import write_contacts

write_contacts(sys.argv[1], sys.argv[2], sys.argv[3])
PY
echo "wrote $out/contacts.md"
