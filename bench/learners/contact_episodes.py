"""Contact detection and contact immunity on a simulated payload log with injected contact episodes.

15 contacts (0.2–3 s, 5–30 N, random directions, seed 7) added to the measured wrench of a 120 s payload
log (pickup at 60 s), run through OnlineEstimator with the gate on and off; detection = any component of
``~/external_wrench`` beyond 5 σ (core/stream/episodes.py), after the 10 s warm-up. Prints one JSON line per
run.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=$PWD .venv/bin/python bench/learners/contact_episodes.py BAG
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from adaptation import run

from semiparam_ros.core.stream.episodes import flag_samples, score_episodes

STARTS = (14, 19, 24, 29, 34, 39, 44, 49, 54, 75, 82, 89, 96, 103, 110)


def main(bag: str) -> None:
    rng = np.random.default_rng(7)
    contacts = []
    for s in STARTS:
        d, mag, u = rng.uniform(0.2, 3.0), rng.uniform(5, 30), rng.normal(size=3)
        contacts.append((float(s), float(d), mag * u / np.linalg.norm(u)))
    episodes = np.array([[s, s + d] for s, d, _ in contacts])
    big = np.array([np.linalg.norm(f) for *_, f in contacts]) >= 10.0
    for gate in (True, False):
        res = run(bag, {"gate.enabled": gate}, contacts=contacts,
                  config_path=Path(__file__).resolve().parents[2] / "config" / "icub_right_arm.yaml")
        t, e = res["t"], res["y"] - res["yhat"]
        warm = t >= 10.0
        score = score_episodes(t[warm], flag_samples(e, res["std"], 5.0)[warm], episodes, tolerance_s=0.2)

        def rmse(a: float, b: float, t=t, e=e) -> float:
            m = (t >= a) & (t < b)
            return float(np.sqrt(np.mean(e[m, :3] ** 2)))

        print(json.dumps(dict(gate=gate, recall=score.recall,
                              recall_ge_10N=float(np.mean(score.detected[big])),
                              false_alarms_per_minute=score.false_alarms_per_minute,
                              median_delay_s=float(np.nanmedian(score.delays_s)),
                              force_rmse_before_first_contact=rmse(10.0, 14.0),
                              force_rmse_after_last_contact_before_pickup=rmse(55.0, 59.5),
                              not_learned=res["not_learned"])))


if __name__ == "__main__":
    main(sys.argv[1])
