"""Public contracts inside the package: no module reaches into another's private members; the learners
satisfy the Learner protocol; the checkpoint fingerprint follows the parameter table's structural flags."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import semiparam_ros
from semiparam_ros.core.config import ICUB_RIGHT_ARM, PARAMETERS, EstimatorConfig, structural_values
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.learners.contract import Learner
from semiparam_ros.errors import CheckpointError

PACKAGE = Path(semiparam_ros.__file__).parent


def _defined_names(tree: ast.AST) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            names.add(node.value)  # __slots__
    return names


def test_no_module_uses_another_modules_private_members():
    offences = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        own = _defined_names(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                continue
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if node.attr not in own:  # an object of another module's class
                offences.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {ast.unparse(node)}")
    assert offences == []


@pytest.mark.parametrize("combination", ["cascade", "consistent", "joint"])
@pytest.mark.parametrize("kind", ["P", "NP", "SP"])
def test_every_learner_satisfies_the_learner_protocol(kind, combination):
    cfg = EstimatorConfig.from_flat(ICUB_RIGHT_ARM).with_overrides({
        "semiparametric.combination": combination, "nonparametric.n_features": 8,
        "parametric.forgetting": 1.0, "nonparametric.forgetting": 1.0})
    model = OnlineEstimator(cfg, kind=kind).model
    assert isinstance(model, Learner)
    stages = model.rls_stages()
    assert set(map(id, model.adaptive_stages())) <= set(map(id, stages))
    # the consistent SP keeps a fast tracker whose memory adaptation does not set
    assert len(stages) - len(model.adaptive_stages()) == (kind == "SP" and combination == "consistent")


def test_fingerprint_names_exactly_the_structural_parameters_that_apply(tmp_path):
    cfg = EstimatorConfig.from_flat(ICUB_RIGHT_ARM).with_overrides({"nonparametric.n_features": 20})
    values = structural_values(cfg, "SP")
    flagged = {s.name for s in PARAMETERS if s.structural}
    assert set(values) <= flagged and "nonparametric.n_features" in values
    assert not {s.name for s in PARAMETERS if not s.structural} & set(values)
    est = OnlineEstimator(cfg)
    path = tmp_path / "m.npz"
    est.save(path)
    # a run-time (non-structural) change: the checkpoint loads
    OnlineEstimator(cfg.with_overrides({"gate.threshold": 7.0, "sync.tolerance": 0.002})).load(path)
    # a structural one: refused, naming it
    with pytest.raises(CheckpointError, match=r"nonparametric\.sigma"):
        OnlineEstimator(cfg.with_overrides({"nonparametric.sigma": 3.0})).load(path)
    # a legacy default leaves the key out: the combination is named only when it is not the cascade
    assert "semiparametric.combination" not in structural_values(
        cfg.with_overrides({"semiparametric.combination": "cascade"}), "SP")
