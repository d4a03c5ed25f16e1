"""Test-suite set-up: ``test/`` on the import path, so every test module imports the shared ``helpers``."""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
