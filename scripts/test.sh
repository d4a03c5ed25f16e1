#!/usr/bin/env bash
# Set up (idempotent) and run the whole test suite: lint, type check (core, io, ros), then pytest.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
bash scripts/setup.sh
.venv/bin/ruff check semiparam_ros test bench launch docs/tools
.venv/bin/python -m mypy  # files and options: [mypy] in setup.cfg
exec .venv/bin/python -m pytest "$@"
