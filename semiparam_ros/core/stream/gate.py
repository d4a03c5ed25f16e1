"""Contact-aware learning gate: predict every sample, learn only those the model can explain.

An external force on the robot (a person pushing the arm, a contact with the table) adds to the measured
wrench or joint torques something the dynamics model must not learn: the downstream use of the model is
to measure exactly that difference (``measured − predicted``), and a model that has absorbed the contact
reports none afterwards. A new payload, on the other hand, is a change of the robot that the model must
adopt. Both show up the same way at first — a residual far beyond the predictive uncertainty — and differ
only in how long they last.

Rule
----
A sample is an *outlier* when any output component's a-priori residual exceeds ``threshold`` predictive
standard deviations: ``max_k |y_k − ŷ_k| / σ_k > threshold``, σ from
:class:`~semiparam_ros.core.learners.uncertainty.NoiseScale` (noise and model uncertainty). An *excursion* is
a run of consecutive outlier samples; it starts at the stamp of its first sample.

- inside the threshold: learned (the excursion, if any, ends);
- an outlier within ``max_contact_duration`` seconds of its excursion's start: **gated** (predicted,
  published, not learned; the noise estimate skips it too);
- an outlier later than that: **adopted** — the change has outlasted any contact we expect, so it is a
  new normal (a payload, a tool change) and is learned; learning shrinks the residual, the noise estimate
  widens σ meanwhile, and the excursion ends by itself once the model has caught up;
- during the first ``warmup`` seconds after the first sample (or a reset) everything is learned: the
  model starts from zero parameters and σ is not yet meaningful;
- an outlier where the model's own relative predictive variance ``v = z A⁻¹ zᵀ`` exceeds ``novelty`` is
  **novel** motion, learned: the model says it has not seen the state (its uncertainty there is above the
  noise's), so a large error is its ignorance, not a force. On the real KUKA logs, ``v`` has a median
  of 0.03 and a 99th percentile of 0.3 on the motion learned, and a median of 5.8 on the samples a new,
  faster motion made outliers. A contact in a never-seen state is learned too: the price of not treating
  every new motion as a contact.

Why time and not size: a contact and a payload can have the same magnitude (a 0.5 kg object weighs
4.9 N, a light push is 5 N), but a contact is transient — a push or a bump lasts a fraction of a second
to a couple of seconds — while a payload stays. Any size-based rule would either learn pushes or refuse
payloads. The price is that a payload is adopted ``max_contact_duration`` seconds late, and that a contact
held longer than that (leaning on the arm) is learned; 3 s by default, longer than the longest contact
expected in normal interaction. The time is measured on the sample stamps, so the rule is rate-independent.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from semiparam_ros.errors import ConfigurationError

__all__ = ["ContactGate", "GateConfig", "Verdict", "exceeds"]


@njit(cache=True, nogil=True)
def exceeds(e: np.ndarray, s: np.ndarray, threshold: float) -> bool:
    """``any(|e_k| > threshold · s_k)`` (no division: σ may be 0 or inf; a NaN compares false)."""
    for k in range(e.shape[0]):
        if abs(e[k]) > threshold * s[k]:
            return True
    return False


class Verdict(enum.Enum):
    """What the gate decided for one sample."""

    WARMUP = "warmup"    #: learned: the gate is not engaged yet
    INLIER = "inlier"    #: learned: residual within the threshold
    GATED = "gated"      #: not learned: an excursion younger than max_contact_duration (a contact)
    ADOPTED = "adopted"  #: learned: an excursion older than max_contact_duration (a new normal)
    NOVEL = "novel"      #: learned: an outlier where the model says it does not know the state

    @property
    def learn(self) -> bool:
        """Whether a sample with this verdict is learned."""
        return self is not Verdict.GATED


@dataclass(frozen=True)
class GateConfig:
    """The gate's parameters (``gate.*`` of the configuration).

    Attributes:
        threshold: Residual bound in predictive standard deviations (> 0).
        max_contact_duration_s: Excursions lasting longer are adopted [s] (≥ 0).
        warmup_s: Time from the first sample during which everything is learned [s] (≥ 0).
        novelty: Relative predictive variance above which an outlier is novel motion (≥ 0; 0 = never).

    Raises:
        ConfigurationError: On a value outside its range (the message names the parameter).
    """

    threshold: float = 5.0
    max_contact_duration_s: float = 3.0
    warmup_s: float = 10.0
    novelty: float = 1.0

    def __post_init__(self) -> None:
        for name, value, positive in (("gate.threshold", self.threshold, True),
                                      ("gate.max_contact_duration", self.max_contact_duration_s, False),
                                      ("gate.warmup", self.warmup_s, False),
                                      ("gate.novelty", self.novelty, False)):
            v = float(value)
            if not math.isfinite(v) or v < 0.0 or (positive and v == 0.0):
                bound = ">" if positive else ">="
                raise ConfigurationError(
                    f"parameter '{name}' must be a finite number {bound} 0, got {value!r}")


class ContactGate:
    """Decides, per sample, whether to learn it (see the module docstring for the rule).

    Args:
        config: The gate's parameters.

    Attributes:
        counts: Samples per verdict since the start or the last reset.
        in_excursion: Whether the last sample was an outlier.
    """

    def __init__(self, config: GateConfig | None = None) -> None:
        self.config = config if config is not None else GateConfig()
        self.reset()

    def reset(self) -> None:
        """Restart: warm-up again, no excursion, counts to zero."""
        self._first_ns: int | None = None
        self._excursion_ns: int | None = None
        self._warm = False  # the warm-up is over (stays so across recordings, see restart_stream)
        self.counts: dict[Verdict, int] = dict.fromkeys(Verdict, 0)

    def restart_stream(self) -> None:
        """Begin a new recording, whose stamps may lie before the last one.

        No excursion is open; a warm-up already over stays over (the model it protects is not new), one
        still running restarts.
        """
        self._excursion_ns = None
        if not self._warm:
            self._first_ns = None

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return what outlives a restart: whether the warm-up is over, and the counts per verdict.

        An open excursion is not saved: its start is a stamp of the stream that ended.
        """
        return {f"{prefix}warm": np.array(int(self._warm), dtype=np.int64),
                f"{prefix}counts": np.array([self.counts[v] for v in Verdict], dtype=np.int64)}

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Restore :meth:`state_dict`'s arrays (validated before anything changes).

        Raises:
            KeyError: A key is missing.
            ValueError: Wrong sizes or negative counts.
        """
        warm = int(np.asarray(state[f"{prefix}warm"]))
        counts = np.asarray(state[f"{prefix}counts"]).reshape(-1)
        if warm not in (0, 1) or counts.shape != (len(Verdict),) or (counts < 0).any():
            raise ValueError(f"gate state is corrupt: warm={warm}, counts={counts}")
        self.reset()
        self._warm = bool(warm)
        self.counts = {v: int(c) for v, c in zip(Verdict, counts, strict=True)}

    @property
    def in_excursion(self) -> bool:
        """Whether the last sample was an outlier (a contact, or a change being adopted)."""
        return self._excursion_ns is not None

    def decide(self, stamp_ns: int, error: np.ndarray, std: np.ndarray, novelty: float = 0.0) -> Verdict:
        """Classify one sample from its a-priori residual and predictive standard deviation.

        Args:
            stamp_ns: Sample stamp [ns].
            error: (t,) ``y − ŷ`` [units of y].
            std: (t,) predictive σ ≥ 0 [units of y] (+inf: anything is plausible).
            novelty: The prediction's relative predictive variance ``v`` (largest over the outputs;
                dimensionless; 0 when unknown).

        Returns:
            The verdict; :attr:`Verdict.learn` says whether to learn the sample.
        """
        cfg = self.config
        if self._first_ns is None:
            self._first_ns = int(stamp_ns)
        if not self._warm and (stamp_ns - self._first_ns) * 1e-9 < cfg.warmup_s:
            verdict = Verdict.WARMUP
            self._excursion_ns = None
        else:
            self._warm = True
            e = np.asarray(error, dtype=np.float64)
            s = np.asarray(std, dtype=np.float64)
            if e.ndim == 1 and e.shape == s.shape:
                outlier = exceeds(e, s, float(cfg.threshold))  # the expression below, compiled
            else:
                # |e| > threshold·σ, written without a division (σ may be 0 or inf)
                outlier = bool(np.any(np.abs(e) > cfg.threshold * s))
            if not outlier:
                verdict = Verdict.INLIER
                self._excursion_ns = None
            elif cfg.novelty > 0.0 and novelty > cfg.novelty:
                verdict = Verdict.NOVEL
                self._excursion_ns = None
            else:
                if self._excursion_ns is None:
                    self._excursion_ns = int(stamp_ns)
                held = (stamp_ns - self._excursion_ns) * 1e-9
                verdict = Verdict.ADOPTED if held > cfg.max_contact_duration_s else Verdict.GATED
        self.counts[verdict] += 1
        return verdict
