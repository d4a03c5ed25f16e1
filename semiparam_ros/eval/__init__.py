"""Measurements on arrays and bags, in three rooms.

:mod:`~semiparam_ros.eval.protocol` — the paper's test-then-train protocol on arrays, its metrics,
horizons, paired comparisons and the typed report; :mod:`~semiparam_ros.eval.models` — the reference
models the protocol runs beside the learners (persistence, fixed or batch-fitted parameters, the served
model, the node's step, a frozen rigid body); :mod:`~semiparam_ros.eval.bags` — bag runs (replay into
arrays, contact detection). Parallel jobs and the Dask cluster are :mod:`semiparam_ros.jobs`.
"""

__all__ = [
    "bags",
    "models",
    "protocol",
]
