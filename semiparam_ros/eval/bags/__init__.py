"""Evaluation runs on bags: replay into the protocol's arrays, and the contact-detection run.

:mod:`~semiparam_ros.eval.bags.replay` reads a bag through the node's pipeline into
:class:`~semiparam_ros.eval.protocol.prequential.SampleArrays` and runs the protocol on a training and a
test bag; :mod:`~semiparam_ros.eval.bags.contact_detection` replays a bag through the estimator with its
contact gate and scores detection against the simulator's ground truth.
"""

__all__ = [
    "contact_detection",
    "replay",
]
