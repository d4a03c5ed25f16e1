"""The reference pages cannot drift: generated from the code, and checked against it here.

The parameter page against ``estimator --print-defaults`` (every parameter with its default), both pages
against a fresh rendering (``python -m docs.tools.reference`` rewrites them).
"""

from __future__ import annotations

import re
import subprocess
import sys

from helpers import REPO

from docs.tools.reference import PAGES, main


def test_committed_reference_pages_are_current(capsys):
    assert main(["--check"]) == 0, capsys.readouterr().err
    assert len(PAGES) == 3


def test_every_printed_default_is_in_the_parameter_reference():
    """Run the installed command as a user would; each line's name and default are a row of the page."""
    out = subprocess.run([sys.executable, "-m", "semiparam_ros.ros.main", "--print-defaults"],
                         capture_output=True, text=True, check=True, cwd=REPO).stdout
    page = (REPO / "docs" / "reference" / "parameters.md").read_text(encoding="utf-8")
    rows = {m[1]: m[2] for m in re.finditer(r"^\| `([\w.]+)` \| [^|]+ \|(?:[^|]|\\\|)+\| `([^`]*)` \|", page,
                                             re.M)}
    line_re = re.compile(r"([\w.]+) \((?:[^()]|\([^)]*\))*, default (.*?)(?:, settable at run time)?\): ")
    lines = [line for line in out.splitlines() if not line.startswith("#")]
    printed = [line_re.match(line) for line in lines]
    assert printed and all(printed), [line for line, m in zip(lines, printed, strict=True) if not m]
    assert {m[1]: m[2] for m in printed} == rows
