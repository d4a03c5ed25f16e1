"""Contacts are neither learned nor hidden, a payload is adopted, and the published σ is calibrated.

Offline, through :class:`OnlineEstimator` (the node's data path), on the committed synthetic bags:

* the external wrench ``y − ŷ`` against the wrench decoded a second time from the bag;
* gate off reproduces the paper's predict-then-learn loop bit for bit (a hand-written loop over
  ``build_pipeline``/``build_model``);
* an injected contact (a force added to the measured wrench for 1.5 s) is absorbed with the gate off and
  not with it on, judged by the error against the *uncontacted* measurement;
* the payload bag's pickup is adopted with the gate on;
* ±2σ coverage on a log held out from every choice of the uncertainty parameters (``icub_xz``; the noise
  time constant was chosen on a separately simulated payload log, docs/adaptation.md).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from helpers import REPO
from threadpoolctl import threadpool_limits

from semiparam_ros.core.config import load_config
from semiparam_ros.core.estimator.build import build_model, build_pipeline
from semiparam_ros.core.estimator.online import OnlineEstimator
from semiparam_ros.core.stream.gate import Verdict
from semiparam_ros.core.stream.messages import JointStateData, WrenchData
from semiparam_ros.io.bags import read_messages

ROOT = REPO
CONFIG = ROOT / "config" / "icub_right_arm.yaml"
BAGS = ROOT / "bags"
FAST = {"nonparametric.n_features": 100}
# start [s from the first wrench], duration [s], force [N]
CONTACT = (25.0, 1.5, np.array([12.0, -15.0, 5.0]))


@dataclasses.dataclass
class Run:
    t: np.ndarray        # s from the first sample
    stamps: np.ndarray   # ns
    y: np.ndarray        # measured (with the injected contact)
    clean: np.ndarray    # measured without the contact
    total: np.ndarray    # a-priori prediction
    external: np.ndarray
    std: np.ndarray
    verdicts: list
    estimator: OnlineEstimator


@functools.cache
def run(bag: str, overrides: tuple, contact: bool = False) -> Run:
    # one BLAS thread, as the node runs: the solves are small and extra threads only spin on a loaded CPU
    with threadpool_limits(1):
        return _run(bag, overrides, contact)


def _run(bag: str, overrides: tuple, contact: bool) -> Run:
    est = OnlineEstimator(load_config(CONFIG).with_overrides(dict(overrides)))
    t0 = None
    clean_by_stamp = {}
    rows = []
    for msg in read_messages(BAGS / bag):
        if isinstance(msg, WrenchData):
            t0 = msg.stamp_ns if t0 is None else t0
            clean_by_stamp[msg.stamp_ns] = np.concatenate([msg.force, msg.torque])
            start, duration, force = CONTACT
            if contact and start <= (msg.stamp_ns - t0) * 1e-9 < start + duration:
                msg = dataclasses.replace(msg, force=msg.force + force)
            results = est.process(msg)
        else:
            results = est.process(msg)
        rows += results
    stamps = np.array([r.sample.stamp_ns for r in rows])
    return Run(t=(stamps - t0) * 1e-9, stamps=stamps, y=np.array([r.sample.y for r in rows]),
               clean=np.array([clean_by_stamp[s] for s in stamps]),
               total=np.array([r.prediction.total for r in rows]),
               external=np.array([r.external for r in rows]), std=np.array([r.std for r in rows]),
               verdicts=[r.verdict for r in rows], estimator=est)


def _rmse(r: Run, a: float, b: float, cols: slice = slice(0, 3)) -> float:
    m = (r.t >= a) & (r.t < b)
    return float(np.sqrt(np.mean((r.clean[m, cols] - r.total[m, cols]) ** 2)))


def test_external_wrench_is_measured_minus_predicted_per_stamp():
    r = run("icub_xy", tuple(FAST.items()))
    # the measured wrench decoded again, independently of the estimator's pipeline
    measured = {m.stamp_ns: np.concatenate([m.force, m.torque])
                for m in read_messages(BAGS / "icub_xy", joint_states_topic=None)}
    assert len(r.stamps) > 3900
    y = np.array([measured[s] for s in r.stamps])
    np.testing.assert_array_equal(r.external, y - r.total)  # one subtraction: exact
    assert np.all(np.isinf(r.std[0]))  # nothing known before the first sample
    assert np.all(np.isfinite(r.std[1:])) and np.all(r.std[1:] > 0)


def test_gate_off_is_the_papers_predict_then_learn_bit_for_bit():
    overrides = {**FAST, "gate.enabled": False, "adaptation.time_constant": 0.0,
                 "semiparametric.combination": "cascade"}  # the paper's learner
    r = run("icub_payload", tuple(overrides.items()))
    config = load_config(CONFIG).with_overrides(overrides)
    pipeline, model = build_pipeline(config), build_model(config, "SP")
    totals = []
    for msg in read_messages(BAGS / "icub_payload"):
        samples = pipeline.add(msg)
        assert isinstance(msg, JointStateData | WrenchData)
        totals += [model.predict_learn_one(s.x, s.y).total for s in samples]
    np.testing.assert_array_equal(r.total, np.array(totals))
    assert r.estimator.not_learned == {"gated_contact": 0}


@pytest.mark.parametrize("gate", [False, True])
def test_contact_is_absorbed_without_the_gate_and_not_with_it(gate):
    r = run("icub_xy", tuple({**FAST, "gate.enabled": gate}.items()), contact=True)
    start, duration, _ = CONTACT
    before = _rmse(r, start - 3.0, start)
    after = _rmse(r, start + duration, start + duration + 3.0)
    gated = sum(v is Verdict.GATED for v in r.verdicts)
    if gate:
        # every contact sample (1.5 s at 100 Hz) refused, nothing learned from it: the error after the
        # contact stays within 10 % of the error before (the acceptance bound)
        assert gated >= 140, gated
        assert after <= 1.1 * before, (before, after)
        # and the contact is reported: the external wrench during it is the injected force ± noise
        m = (r.t >= start + 0.1) & (r.t < start + duration)
        np.testing.assert_allclose(np.median(r.external[m, :3], axis=0), CONTACT[2], atol=1.0)
    else:
        assert gated == 0
        assert after > 1.5 * before, (before, after)


def test_payload_is_adopted_with_the_gate_on():
    on = run("icub_payload", tuple({**FAST, "gate.enabled": True}.items()))
    off = run("icub_payload", tuple({**FAST, "gate.enabled": False}.items()))
    paper_learner = {**FAST, "gate.enabled": False, "adaptation.time_constant": 0.0,
                     "parametric.forgetting": 1.0, "nonparametric.forgetting": 1.0,
                     "semiparametric.combination": "cascade"}
    paper = run("icub_payload", tuple(paper_learner.items()))
    pickup = 19.8  # scenario.yaml: payload at 20 s of the bag, the first wrench at 0.2 s
    assert sum(v is Verdict.ADOPTED for v in on.verdicts) > 0
    gated = [t for t, v in zip(on.t, on.verdicts, strict=True) if v is Verdict.GATED]
    # refused only from the pickup for gate.max_contact_duration (3 s), then adopted
    assert gated and min(gated) >= pickup - 0.05 and max(gated) <= pickup + 3.0 + 0.5
    # from 4 s after the pickup on: as accurate as without the gate (10 %), and better than the paper's
    # learner without forgetting (measured ratio ≈ 0.8 on this bag; D = 100)
    late_on, late_off, late_paper = (_rmse(r, pickup + 4.0, 40.0) for r in (on, off, paper))
    assert late_on <= 1.1 * late_off, (late_on, late_off)
    assert late_on < 0.9 * late_paper, (late_on, late_paper)


@pytest.mark.parametrize("gate", [False, True])
def test_two_sigma_coverage_on_a_held_out_log(gate):
    r = run("icub_xz", tuple({**FAST, "gate.enabled": gate}.items()))
    warm = r.t >= r.estimator.config["gate.warmup"]
    inside = np.abs(r.y - r.total)[warm] <= 2.0 * r.std[warm]
    for name, cols in (("force", slice(0, 3)), ("torque", slice(3, 6))):
        coverage = float(np.mean(inside[:, cols]))
        assert 0.90 <= coverage <= 0.98, (name, coverage)
