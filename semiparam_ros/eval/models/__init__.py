"""Reference models the protocol runs beside the learners (each an ``OnlineModel``).

:mod:`~semiparam_ros.eval.models.baselines` — persistence (the previous measured output), fixed
parameters (the CAD model) and batch least squares; :mod:`~semiparam_ros.eval.models.served` — the model
as ``load_model`` serves it and the node's per-sample step; :mod:`~semiparam_ros.eval.models.frozen` — a
cascade whose rigid body stops learning after training.
"""

__all__ = [
    "baselines",
    "frozen",
    "served",
]
