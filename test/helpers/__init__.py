"""Helpers the tests share: paths, references computed independently of the package, streams and bags.

Test modules import from here only (never from one another); ``test/conftest.py`` puts ``test/`` on the
import path, so ``from helpers.ros import NodeProcess`` works from any folder of the mirror.
"""

from pathlib import Path

#: The repository's root (``test/helpers/__init__.py`` → two folders up).
REPO = Path(__file__).resolve().parents[2]
#: The real KUKA LWR4+ logs beside the repository (present on the developers' machines and in CI).
KUKA = REPO.parent / "shared" / "data" / "kuka_lwr4"
