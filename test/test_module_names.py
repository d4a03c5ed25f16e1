"""Every module path the docstrings, comments and pages name exists: a renamed or removed module leaves no
stale name behind. Checked: absolute dotted names (``semiparam_ros.core.learners.rrls.RecursiveRLS``),
names relative to the package in backticks (``core.learners.rrls``) and package paths
(``core/learners/rrls.py``). Test files named by a path relative to ``test/`` are not package paths; the
code's own references are checked by importing it."""

from __future__ import annotations

import importlib
import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "semiparam_ros"
ROOMS = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file())
ABSOLUTE = re.compile(r"\bsemiparam_ros(?:\.[A-Za-z_]\w*)+")
RELATIVE = re.compile(r"(?<=`)(?:" + "|".join(ROOMS) + r")(?:\.[a-z_]\w*)+(?<!\.py)(?=`)")
PATH = re.compile(r"(?<![\w./-])(?:semiparam_ros/)?(?:" + "|".join(ROOMS) + r")/[\w/]*\w\.py\b")
TRIPLE_QUOTES = ('"""', "'" * 3)


def _sources() -> list[Path]:
    """The Python files of the package, the tests, the benchmarks and the docs tools."""
    files = [*PACKAGE.rglob("*.py"), *(ROOT / "test").rglob("*.py"), *(ROOT / "bench").rglob("*.py"),
             *(ROOT / "docs" / "tools").glob("*.py")]
    return sorted(f for f in files if "__pycache__" not in f.parts and f != Path(__file__).resolve())


def _pages() -> list[Path]:
    """The README, the docs' pages and their templates."""
    docs = ROOT / "docs"
    return sorted([ROOT / "README.md", *docs.glob("*.md"), *(docs / "templates").glob("*.in")])


def _prose(path: Path) -> str:
    """Docstrings and comments of a Python file (the whole text of a page)."""
    if path.suffix != ".py":
        return path.read_text()
    parts: list[str] = []
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        docstring = tok.type == tokenize.STRING and tok.string.lstrip("rbuf").startswith(TRIPLE_QUOTES)
        if tok.type == tokenize.COMMENT or docstring:
            parts.append(tok.string)
    return "\n".join(parts)


def _resolves(dotted: str) -> bool:
    """Whether a dotted name is a module, or a module followed by attributes it has."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def _stale(path: Path) -> list[str]:
    text = _prose(path)
    names = set(ABSOLUTE.findall(text)) | {f"semiparam_ros.{m}" for m in RELATIVE.findall(text)}
    bad = sorted(n for n in names if not _resolves(n.rstrip(".")))
    paths = {p if p.startswith("semiparam_ros/") else f"semiparam_ros/{p}" for p in PATH.findall(text)
             if not Path(p).name.startswith("test_")}
    return bad + sorted(p for p in paths if not (ROOT / p).is_file())


@pytest.mark.parametrize("path", _sources() + _pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_named_module_exists(path):
    assert _stale(path) == [], f"{path.relative_to(ROOT)} names modules that do not exist"


def test_a_stale_name_is_found():
    """The check itself: a removed module, a missing attribute and a missing file are each reported."""
    assert not _resolves("semiparam_ros.core.rrls") and not _resolves("semiparam_ros.core.config.NoSuchThing")
    assert _resolves("semiparam_ros.core.learners.rrls.RecursiveRLS")
    assert PATH.findall("see core/learners/rrls.py and service/serving.py") == [
        "core/learners/rrls.py"]  # service/ is no room of the package: not matched, not a path of it
    found = RELATIVE.findall("``core.rrls`` and `eval.horizon`, not report.json nor `report.py`")
    assert found == ["core.rrls", "eval.horizon"]
