"""The documentation as a user meets it: an index that reaches every page, links that resolve (files and
anchors, GitHub's slugs), no lab notebook (issue numbers, "(third part)" chapters), guides within their
budget, and the guides' runnable command blocks run (from a scratch folder, as a user would)."""

from __future__ import annotations

import os
import re
import subprocess
import unicodedata

import pytest
from helpers import REPO

DOCS = REPO / "docs"
PAGES = sorted([*DOCS.glob("*.md"), *(DOCS / "reference").glob("*.md")])
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_ORDINALS = "first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth"
LAB_NOTEBOOK = re.compile(rf"issue [0-9]+|({_ORDINALS}) part", re.I)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped (letters of any script kept), spaces
    to hyphens."""
    text = heading.strip().lower()
    text = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return text.replace(" ", "-")


def _anchors(path):
    inside = False
    anchors = set()
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            inside = not inside
        elif not inside and line.startswith("#"):
            anchors.add(slug(line.lstrip("#")))
    return anchors


def test_the_index_reaches_every_page_under_one_kind():
    index = (DOCS / "README.md").read_text(encoding="utf-8")
    sections = re.split(r"^## ", index, flags=re.M)
    kinds = {s.split("\n", 1)[0].split(" (")[0]: s for s in sections[1:]}
    assert {"Guides", "Reference", "Explanation", "Reports"} <= set(kinds)
    for page in PAGES:
        if page.name == "README.md" and page.parent == DOCS:
            continue
        rel = page.relative_to(DOCS).as_posix()
        homes = [k for k in ("Guides", "Reference", "Explanation", "Reports") if f"]({rel})" in kinds[k]]
        assert len(homes) == 1, (rel, homes)


def test_every_link_resolves():
    bad = []
    for page in [*PAGES, REPO / "README.md"]:
        for target in LINK.findall(page.read_text(encoding="utf-8")):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            if not dest.exists():
                bad.append(f"{page.relative_to(REPO)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                bad.append(f"{page.relative_to(REPO)}: {target} (no such heading)")
    assert bad == []


def test_no_lab_notebook_in_the_docs():
    pages = [*DOCS.glob("*.md"), REPO / "README.md"]
    hits = [f"{p.relative_to(REPO)}:{i}: {line.strip()}" for p in pages
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
            if LAB_NOTEBOOK.search(line)]
    assert hits == []


def test_guides_stay_within_their_budget():
    index = (DOCS / "README.md").read_text(encoding="utf-8")
    guides = re.split(r"^## ", index, flags=re.M)
    section = next(s for s in guides if s.startswith("Guides"))
    pages = re.findall(r"\]\(([\w.-]+\.md)\)", section)
    lines = sum(len((DOCS / p).read_text(encoding="utf-8").splitlines()) for p in pages)
    assert len(pages) >= 6 and lines <= 1500, (pages, lines)


def _runnable_blocks():
    blocks = []
    for page in DOCS.glob("*.md"):
        text = page.read_text(encoding="utf-8")
        for match in re.finditer(r"<!-- runnable -->\n```bash\n(.*?)```", text, re.S):
            blocks.append(pytest.param(match[1], id=page.stem))
    return blocks


@pytest.mark.slow
@pytest.mark.parametrize("block", _runnable_blocks())
def test_runnable_blocks_run_as_written(block, tmp_path):
    """From a scratch folder holding the repository's config/ and .venv/, as the guides assume."""
    for name in ("config", ".venv"):
        (tmp_path / name).symlink_to(REPO / name)
    env = {**os.environ, "ROS_HOME": str(tmp_path / "ros_home"), "COLUMNS": "100"}
    proc = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", block], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
