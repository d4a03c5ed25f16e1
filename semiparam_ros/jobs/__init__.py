"""Jobs in parallel, for the evaluation, selection and fleets alike.

Local processes (:mod:`~semiparam_ros.jobs.parallel`) or a Dask cluster (:mod:`~semiparam_ros.jobs.cluster`).
"""

__all__ = [
    "cluster",
    "parallel",
]
