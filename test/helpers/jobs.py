"""Jobs the cluster tests send to Dask workers.

They live here, not in a test module, because a worker imports a job's module by name: test modules are
imported under generated names (``--import-mode=importlib``) that no worker can import, while ``helpers``
is on the path the workers inherit (``test/conftest.py``).
"""

from __future__ import annotations

import os
import time
from pathlib import Path


def square_or_die_once(x: int, marker: str) -> int:
    """Return x² after 0.3 s; the first time it runs with x == 3 it kills its worker process instead."""
    time.sleep(0.3)
    if x == 3 and not os.path.exists(marker):
        Path(marker).write_text("killed")
        os._exit(1)  # the worker dies mid-run, its nanny starts another
    return x * x
