"""Per-learner hyperparameter selection from grid runs, and the results section that uses it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from semiparam_ros.eval.compare import compare_pair
from semiparam_ros.eval.results import render_results
from semiparam_ros.eval.selection import select

FIGS = Path(__file__).resolve().parents[1] / "docs" / "figures"


def report(lam, sigma, **models):
    return {"config": {"nonparametric.lam": lam, "nonparametric.sigma": sigma}, "protocol": {"first_s": 3.0},
            "models": {k: {"force_rmse": f, "torque_rmse": t, "force_rmse_first_3s": 10 * f,
                           "torque_rmse_first_3s": 10 * t} for k, (f, t) in models.items()}}


def test_scores_are_relative_to_each_learners_own_best():
    grid = [report(0.001, 6, SP=(0.30, 0.030), NP=(0.33, 0.031)),
            report(0.01, 4, SP=(0.31, 0.029), NP=(0.32, 0.0305)),
            report(0.1, 8, SP=(0.33, 0.033))]
    sp = select(grid, "SP")
    # by hand: best force 0.30, best torque 0.029
    scores = {(p.lam, p.sigma): p.score for p in sp}
    assert scores[(0.001, 6.0)] == pytest.approx(0.30 / 0.30 + 0.030 / 0.029)
    assert scores[(0.01, 4.0)] == pytest.approx(0.31 / 0.30 + 0.029 / 0.029)
    assert scores[(0.1, 8.0)] == pytest.approx(0.33 / 0.30 + 0.033 / 0.029)
    assert [p.score for p in sp] == sorted(p.score for p in sp)
    np_points = select(grid, "NP")  # the third run has no NP: two points, NP's own best values
    assert len(np_points) == 2 and (np_points[0].lam, np_points[0].sigma) == (0.01, 4.0)
    assert np_points[0].score == pytest.approx(2.0)  # NP's best force and best torque both at 0.01, 4
    assert np_points[0].force_first == pytest.approx(3.2)
    assert select(grid, "SPJ") == []


def test_a_report_without_its_configuration_is_refused():
    bad = report(0.001, 6, SP=(0.3, 0.03))
    del bad["config"]["nonparametric.sigma"]
    with pytest.raises(ValueError, match="sigma"):
        select([bad], "SP")


def test_results_page_shows_each_learner_with_its_own_selection():
    paper = json.loads((FIGS / "paper.json").read_text())
    payload = json.loads((FIGS / "payload.json").read_text())
    own = {"NP": paper, "SPJ": paper}  # stand-ins: the section reads each learner from its own report
    text = render_results(paper, payload, figures={"fig3": "f.png", "payload": "p.png"}, own=own)
    assert "### Each learner with its own selection" in text
    section = text.split("### Each learner with its own selection", 1)[1]
    row = next(line for line in section.splitlines() if line.startswith("| SPJ | "))
    expect = compare_pair(paper["models"]["SPJ"]["torque_rmse_splits"],
                          paper["models"]["NP"]["torque_rmse_splits"])
    assert f"{expect['ratio']:.4f}" in row
    assert "### Each learner with its own selection" not in render_results(
        paper, payload, figures={"fig3": "f.png", "payload": "p.png"})
