"""Typed keys and options of an evaluation: which learner variant, and the protocol's settings.

:class:`Variant` names a learner run in a report (its kind, and in the payload scenario whether it adapts
and with which forgetting factors); its :attr:`~Variant.label` is the key written in the JSON reports and
tables, and :meth:`Variant.parse` reads such a key back, so no consumer splits display strings.
:class:`ProtocolOptions` holds the protocol's settings with their defaults in one place.

>>> v = Variant("SP", adaptive=True, beta=0.995)
>>> v.label
'SP adaptive (β=0.995)'
>>> Variant.parse(v.label) == v, Variant.parse("SPJ no adaptation")
(True, Variant(kind='SPJ', adaptive=False, beta=None, beta_np=None))
>>> Variant.parse("NP")
Variant(kind='NP', adaptive=None, beta=None, beta_np=None)
>>> ProtocolOptions().window_s, ProtocolOptions(splits=5).splits
(3.0, 5)
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = [
    "CASCADE_SP", "DEFAULT_FIRST_S", "DEFAULT_SPLITS", "DEFAULT_WINDOW_S", "JOINT_SP", "ProtocolOptions",
    "Variant",
]

#: The joint semiparametric learner
#: (:class:`~semiparam_ros.core.learners.joint.JointSemiparametricModel`): the SP model built with
#: ``semiparametric.combination = joint`` whatever the configuration says.
JOINT_SP = "SPJ"
#: The paper's cascade (:class:`~semiparam_ros.core.learners.cascade.SemiparametricModel`): the SP
#: model built with ``semiparametric.combination = cascade`` whatever the configuration says.
CASCADE_SP = "SPC"

#: Sliding RMSE window [s].
DEFAULT_WINDOW_S = 3.0
#: Initial segment of each test part reported separately [s] (``*_first_3s``).
DEFAULT_FIRST_S = 3.0
#: Sequential test parts.
DEFAULT_SPLITS = 10

_ADAPTIVE = re.compile(
    r"^(?P<kind>\S+) adaptive \((?:β=(?P<beta>[^,)]+)|β_P=(?P<bp>[^,]+), β_NP=(?P<bnp>[^)]+))\)$")


@dataclass(frozen=True)
class Variant:
    """A learner as run in a report.

    Attributes:
        kind: The learner (``P``, ``NP``, ``SP``, ``SPJ``, ``SPC``, ``SPfrozenP``, or a baseline's name).
        adaptive: Payload scenario: True with forgetting, False without; None outside it.
        beta: Forgetting factor of the parametric stage when adaptive (also the residual's when
            ``beta_np`` is None).
        beta_np: Forgetting factor of the residual stage when it differs from ``beta``.
    """

    kind: str
    adaptive: bool | None = None
    beta: float | None = None
    beta_np: float | None = None

    @property
    def label(self) -> str:
        """The key of this variant in reports and tables."""
        if self.adaptive is None:
            return self.kind
        if not self.adaptive:
            return f"{self.kind} no adaptation"
        if self.beta_np is None or self.beta_np == self.beta:
            return f"{self.kind} adaptive (β={self.beta:g})"
        return f"{self.kind} adaptive (β_P={self.beta:g}, β_NP={self.beta_np:g})"

    @classmethod
    def parse(cls, label: str) -> Variant:
        """Read a report key written by :attr:`label`.

        Raises:
            ValueError: A key that names an adaptive variant but whose factors cannot be read.
        """
        if label.endswith(" no adaptation"):
            return cls(label[: -len(" no adaptation")], adaptive=False)
        if " adaptive (" in label:
            m = _ADAPTIVE.match(label)
            if m is None:
                raise ValueError(f"cannot read the learner variant {label!r}")
            if m["beta"] is not None:
                return cls(m["kind"], adaptive=True, beta=float(m["beta"]))
            return cls(m["kind"], adaptive=True, beta=float(m["bp"]), beta_np=float(m["bnp"]))
        return cls(label)


@dataclass(frozen=True)
class ProtocolOptions:
    """The test protocol's settings (the paper's: train on one bag, test-then-train on parts of another).

    Attributes:
        splits: Sequential test parts.
        split_size: Samples per part (None: the test stream in ``splits`` equal parts).
        window_s: Sliding RMSE window [s].
        first_s: Initial segment of each part reported separately [s].
        train_limit: Use only the first training samples (None: all).
        test_limit: Use only the first test samples (None: all).
        test_skip: Drop this many samples at the start of the test stream.
    """

    splits: int = DEFAULT_SPLITS
    split_size: int | None = None
    window_s: float = DEFAULT_WINDOW_S
    first_s: float = DEFAULT_FIRST_S
    train_limit: int | None = None
    test_limit: int | None = None
    test_skip: int = 0
