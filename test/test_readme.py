"""The README's ``>>>`` example runs as written, on a checkpoint written by ``learn`` (its command)."""

from __future__ import annotations

import doctest
import re

import numpy as np
from helpers import REPO

from semiparam_ros.cli import learn as learn_cli
from semiparam_ros.sim.arms import ArmScenarioConfig, simulate_arm
from semiparam_ros.sim.writer import write_recording


def test_readme_python_example_runs(tmp_path, monkeypatch):
    rec = simulate_arm(ArmScenarioConfig(name="panda_log", robot="panda", duration=8.0, rate=200.0, seed=0))
    bag = write_recording(rec, tmp_path / "panda_log")
    assert learn_cli.main([str(bag), "--config", str(REPO / "config" / "panda.yaml"), "--set",
                           "nonparametric.n_features=100", "--checkpoint", str(tmp_path / "panda.npz"),
                           "--quiet"]) == 0
    text = (REPO / "README.md").read_text()
    blocks = [b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S) if ">>>" in b]
    assert blocks, "the README has no >>> example"
    monkeypatch.chdir(tmp_path)
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for i, block in enumerate(blocks):
        test = parser.get_doctest(block, {"np": np}, f"README[{i}]", "README.md", 0)
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0 and result.attempted >= 8
