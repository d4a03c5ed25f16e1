"""Per-learner hyperparameter selection from protocol runs over a grid (``tune --method protocol``)."""

from __future__ import annotations

import json

import pytest
from helpers import REPO

from semiparam_ros.eval.protocol.report import ProtocolReport
from semiparam_ros.tune.selection import score_reports

FIGS = REPO / "docs" / "figures"


def report(lam, sigma, **models) -> ProtocolReport:
    doc = {
        "config": {"parametric.lam": 0.01, "nonparametric.lam": lam, "nonparametric.sigma": sigma},
        "protocol": {"first_s": 3.0},
        "splits": 1,
        "samples_train": 1,
        "samples_test": 1,
        "update_us": {k: 1.0 for k in models},
        "models": {
            k: {
                "force_rmse": f,
                "torque_rmse": t,
                "force_rmse_first_3s": 10 * f,
                "torque_rmse_first_3s": 10 * t,
            }
            for k, (f, t) in models.items()
        },
    }
    return ProtocolReport.from_json(doc)


def test_scores_are_relative_to_each_learners_own_best():
    grid = [
        report(0.001, 6, SP=(0.30, 0.030), NP=(0.33, 0.031)),
        report(0.01, 4, SP=(0.31, 0.029), NP=(0.32, 0.0305)),
        report(0.1, 8, SP=(0.33, 0.033)),
    ]
    sp = score_reports(grid, "SP")
    # by hand: best force 0.30, best torque 0.029
    scores = {(p.values["nonparametric.lam"], p.values["nonparametric.sigma"]): p.score for p in sp}
    assert scores[(0.001, 6.0)] == pytest.approx(0.30 / 0.30 + 0.030 / 0.029)
    assert scores[(0.01, 4.0)] == pytest.approx(0.31 / 0.30 + 0.029 / 0.029)
    assert scores[(0.1, 8.0)] == pytest.approx(0.33 / 0.30 + 0.033 / 0.029)
    assert [p.score for p in sp] == sorted(p.score for p in sp)
    np_points = score_reports(grid, "NP")  # the third run has no NP: two points, NP's own best values
    assert len(np_points) == 2 and np_points[0].values["nonparametric.lam"] == 0.01
    assert np_points[0].score == pytest.approx(2.0)  # NP's best force and best torque both at 0.01, 4
    assert np_points[0].rmse_first["force"] == pytest.approx(3.2)
    assert score_reports(grid, "SPJ") == []


def test_a_report_without_its_configuration_is_refused():
    bad = report(0.001, 6, SP=(0.3, 0.03))
    del bad.config["nonparametric.sigma"]
    with pytest.raises(ValueError, match="sigma"):
        score_reports([bad], "SP")


def test_committed_selection_is_the_score_of_its_runs():
    """select_xy.json (written by `tune --method protocol` in scripts/reproduce.sh) lists, per learner, the
    grid best first: its scores are recomputed here from the runs' RMSEs by the formula, independently."""
    doc = json.loads((FIGS / "select_xy.json").read_text())
    runs = doc["runs"]
    for kind, sel in doc["selections"].items():
        force = [r["models"][kind]["force"] for r in runs]
        torque = [r["models"][kind]["torque"] for r in runs]
        scores = [f / min(force) + t / min(torque) for f, t in zip(force, torque, strict=True)]
        assert [p["score"] for p in sel["grid"]] == pytest.approx(sorted(scores), rel=1e-12)
        best = runs[scores.index(min(scores))]["config"]
        assert sel["best"]["nonparametric.lam"] == best["nonparametric.lam"]
        assert sel["best"]["nonparametric.sigma"] == best["nonparametric.sigma"]
    # the page keeps λ_NP = 0.001, σ = 6 (scripts/paper_params.sh); since every residual learns its
    # warm-up the protocol selection for the cascade is λ_NP = 0.001, σ = 4 (docs/results.md says so)
    assert doc["selections"]["SP"]["best"]["nonparametric.lam"] == 0.001
    assert doc["selections"]["SP"]["best"]["nonparametric.sigma"] in (4.0, 6.0)
