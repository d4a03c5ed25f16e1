"""The paper's protocol on plain arrays, and what is measured and reported of it.

:mod:`~semiparam_ros.eval.protocol.prequential` — train, then test-then-train on sequential parts (and
the adaptation protocol); :mod:`~semiparam_ros.eval.protocol.metrics` — outputs, groups, RMSE and
windows; :mod:`~semiparam_ros.eval.protocol.horizon` — models by age (one step to frozen);
:mod:`~semiparam_ros.eval.protocol.compare` — paired comparisons over parts;
:mod:`~semiparam_ros.eval.protocol.options` — the protocol's options and model keys;
:mod:`~semiparam_ros.eval.protocol.report` — the typed report, its JSON and the paper's criteria.
"""

__all__ = [
    "compare",
    "horizon",
    "metrics",
    "options",
    "prequential",
    "report",
]
