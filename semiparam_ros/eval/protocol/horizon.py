"""How good is a model h seconds old? Learners through a delay line, beside persistence held h.

At 100 Hz–1 kHz the previous measured output predicts the next one very well, so one-step-ahead accuracy
says little about a learned model. What a feed-forward term or a contact detector uses is a model that is
*older* than the sample it predicts: it was learned on data up to ``t − h`` and predicts ``t`` from the
state alone. This module measures exactly that.

**Delay line.** A learner at horizon ``h`` (``d = round(h / T)`` samples, ``d ≥ 1``, T the test stream's
sample period) goes through the test stream as::

    for i in 0 … n−1:
        if i − d ≥ 0: model.learn_one(X[i − d], Y[i − d])
        prediction[i] = model.predict_one(X[i])

so the model predicting sample ``i`` has learned the training stream and every test sample up to
``i − d`` — it is the snapshot of the online model taken ``h`` before ``i``, without storing snapshots.
``d = 1`` is test-then-train (one step ahead); the *frozen* horizon learns no test sample at all, and
uses a learner's model alone (``predict_model`` where it has one: the consistent SP without the fast
correction of its last errors, which exists to track and has nothing to track in a frozen model).
Persistence (:class:`~semiparam_ros.eval.models.baselines.Persistence`) through the same delay line is
persistence *held h*: ``ŷ(t) = y(t − h)``. Models that never learn (the CAD model, a batch fit) give the
same prediction at every horizon.

Every horizon is scored on the same samples: those with index ≥ the largest finite delay (so that
persistence held h has a measurement to hold). The samples are also split by whether the state lies
**inside the training data's range**: every joint's position and velocity within the per-joint
``[min, max]`` of the training stream (:func:`inside_training_range`).

Units: horizons and periods in s; errors in the units of y (N·m for joint torques, N / N·m for a wrench).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semiparam_ros.atomic import atomic_savefig
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.protocol.prequential import SampleArrays, stamps_for
from semiparam_ros.eval.protocol.slices import motion_slices, slice_rmse, slice_shares

__all__ = [
    "DEFAULT_HORIZONS",
    "FROZEN",
    "HEADLINE_HORIZONS",
    "Horizon",
    "HorizonReport",
    "delayed_predictions",
    "evaluate_horizons",
    "horizon_figure",
    "horizon_markdown",
    "inside_training_range",
    "parse_horizons",
]

#: The frozen horizon: no test sample learned.
FROZEN = "frozen"
#: One step, 0.1 s, 1 s, 10 s and frozen (``0`` stands for one sample period).
DEFAULT_HORIZONS: tuple[float | str, ...] = (0.0, 0.1, 1.0, 10.0, FROZEN)


@dataclass(frozen=True)
class Horizon:
    """One horizon of the table.

    Attributes:
        label: ``"1 step"``, ``"0.1 s"``, …, or ``"frozen"``.
        seconds: The age of the model [s] (``math.inf`` when frozen).
        delay: The delay in samples (0 when frozen: no test sample learned).
    """

    label: str
    seconds: float
    delay: int

    @property
    def frozen(self) -> bool:
        """Whether no test sample is learned."""
        return self.delay == 0


def parse_horizons(values: Sequence[float | str], sample_period_s: float) -> list[Horizon]:
    """Turn horizons in seconds (``0`` = one step, ``"frozen"``) into :class:`Horizon` records.

    Args:
        values: Horizons [s] ≥ 0, or :data:`FROZEN`.
        sample_period_s: The test stream's sample period [s], > 0.

    Returns:
        One record per distinct delay, in the given order (a horizon shorter than a period is one step).

    Raises:
        ConfigurationError: On a negative, non-finite or unknown horizon, or a bad period.

    Example:
        >>> [h.label for h in parse_horizons([0, 0.1, 1, "frozen"], 0.005)]
        ['1 step', '0.1 s', '1 s', 'frozen']
        >>> [h.delay for h in parse_horizons([0, 0.1, 1, "frozen"], 0.005)]
        [1, 20, 200, 0]
    """
    if not (math.isfinite(sample_period_s) and sample_period_s > 0):
        raise ConfigurationError(f"sample period must be positive, got {sample_period_s!r}")
    out: list[Horizon] = []
    seen: set[int] = set()
    for v in values:
        if isinstance(v, str) and v.strip().lower() == FROZEN:
            if 0 not in seen:
                out.append(Horizon(FROZEN, math.inf, 0))
                seen.add(0)
            continue
        try:
            h = float(v)
        except ValueError:
            raise ConfigurationError(f"horizon must be seconds >= 0 or {FROZEN!r}, got {v!r}") from None
        if not (math.isfinite(h) and h >= 0):
            raise ConfigurationError(f"horizon must be seconds >= 0 or {FROZEN!r}, got {v!r}")
        d = max(1, round(h / sample_period_s))
        if d in seen:
            continue
        seen.add(d)
        label = "1 step" if d == 1 else f"{h:g} s"
        out.append(Horizon(label, d * sample_period_s, d))
    return out


def delayed_predictions(model: Any, X: np.ndarray, Y: np.ndarray, delay: int,
                        stamps_ns: np.ndarray | None = None) -> np.ndarray:
    """Predict each sample with the model that has learned everything up to ``delay`` samples before it.

    Args:
        model: An online model (``predict_one``, ``learn_one``); updated in place (pass a copy).
        X: Inputs (n, d).
        Y: Measured outputs (n, t).
        delay: ``d ≥ 1`` samples; 0 = frozen (nothing learned).
        stamps_ns: The samples' stamps [ns], given as ``stamp_ns=`` to ``learn_one`` and ``predict_one`` of
            a model that learns with them (the node's estimator: ``needs_stamps``; its fast correction fades
            with the age of the model at the predicted sample).

    Returns:
        Predictions (n, t).

    Raises:
        ConfigurationError: On a negative delay.

    Example:
        >>> import numpy as np
        >>> from semiparam_ros.eval.models.baselines import Persistence
        >>> Y = np.arange(5.0).reshape(-1, 1)
        >>> delayed_predictions(Persistence(1), np.zeros((5, 1)), Y, 2)[:, 0]  # y held 2 samples
        array([0., 0., 0., 1., 2.])
    """
    if delay < 0:
        raise ConfigurationError(f"delay must be >= 0, got {delay}")
    n = X.shape[0]
    out = np.empty((n, Y.shape[1]))
    learns = delay > 0 and callable(getattr(model, "learn_one", None))
    stamps = stamps_for(model, stamps_ns, n) if learns else None
    # frozen, a learner is used as its model: without the fast correction of its recent errors, if it has one
    predict = (getattr(model, "predict_model", None) if delay == 0 else None) or model.predict_one
    for i in range(n):
        if stamps is None:
            if learns and i >= delay:
                model.learn_one(X[i - delay], Y[i - delay])
            pred = predict(X[i])
        else:  # the node's estimator: learned with its stamps, predicting at the model's age at the sample
            if i >= delay:
                model.learn_one(X[i - delay], Y[i - delay], stamp_ns=int(stamps[i - delay]))
            pred = predict(X[i], stamp_ns=int(stamps[i]))
        out[i] = np.asarray(getattr(pred, "total", pred), dtype=np.float64).reshape(-1)
    return out


def inside_training_range(train_X: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Whether each state's joint positions and velocities lie within the training stream's per-joint range.

    Args:
        train_X: Training inputs ``[q, q̇, q̈]`` (m, 3n) [rad, rad/s, rad/s²].
        X: States to classify (k, 3n).

    Returns:
        (k,) bool: every q_j and q̇_j within the training ``[min, max]`` of that joint.

    Example:
        >>> import numpy as np
        >>> train = np.array([[0.0, -1.0, 0.0], [1.0, 1.0, 0.0]])  # one joint: q, dq, ddq
        >>> inside_training_range(train, np.array([[0.5, 0.0, 9.0], [0.5, 2.0, 0.0]])).tolist()
        [True, False]
    """
    n = train_X.shape[1] // 3
    lo = train_X[:, :2 * n].min(axis=0)
    hi = train_X[:, :2 * n].max(axis=0)
    qdq = X[:, :2 * n]
    return np.all((qdq >= lo) & (qdq <= hi), axis=1)


@dataclass(frozen=True)
class HorizonReport:
    """Errors of every model at every horizon, on the common scored samples.

    Attributes:
        horizons: The horizons, in order.
        components: Output component names (joints, or wrench axes).
        rmse: ``rmse[model][horizon label]`` = per-component RMSE (list, units of y) on all scored samples.
        rmse_inside: The same on the scored samples inside the training range (NaN where there are none).
        rmse_outside: The same outside it.
        n_scored: Scored samples (index ≥ the largest finite delay).
        n_inside: Of which inside the training range.
        sample_period_s: The test stream's period [s].
        slices: ``slices[model][horizon label][slice]`` = mean RMSE over the outputs in that motion state
            (:mod:`~semiparam_ros.eval.protocol.slices`), on the scored samples.
        slice_share: Fraction of the scored (sample, output) pairs in each slice.
    """

    horizons: tuple[Horizon, ...]
    components: tuple[str, ...]
    rmse: dict[str, dict[str, list[float]]]
    rmse_inside: dict[str, dict[str, list[float]]]
    rmse_outside: dict[str, dict[str, list[float]]]
    n_scored: int
    n_inside: int
    sample_period_s: float
    slices: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    slice_share: dict[str, float] = field(default_factory=dict)

    @classmethod
    def merge(cls, parts: Sequence[HorizonReport]) -> HorizonReport:
        """One report of the models of several reports on the same streams and horizons, in their order.

        Raises:
            ValueError: If the reports' horizons or scored samples differ.
        """
        first = parts[0]
        if any(p.horizons != first.horizons or p.n_scored != first.n_scored for p in parts):
            raise ValueError("reports merged must share their horizons and scored samples")
        return cls(first.horizons, first.components,
                   {m: v for p in parts for m, v in p.rmse.items()},
                   {m: v for p in parts for m, v in p.rmse_inside.items()},
                   {m: v for p in parts for m, v in p.rmse_outside.items()},
                   first.n_scored, first.n_inside, first.sample_period_s,
                   {m: v for p in parts for m, v in p.slices.items()}, first.slice_share)

    def mean(self, model: str, horizon: str, subset: str = "all") -> float:
        """Mean over the components of the RMSE of ``model`` at ``horizon`` (subset all/inside/outside)."""
        table = {"all": self.rmse, "inside": self.rmse_inside, "outside": self.rmse_outside}[subset]
        values = table[model][horizon]
        return float(np.mean(values))

    def to_json(self) -> dict[str, Any]:
        """Plain-JSON form (means over the components included)."""
        def means(table: dict[str, dict[str, list[float]]]) -> dict[str, dict[str, float]]:
            return {m: {h: float(np.mean(v)) for h, v in row.items()} for m, row in table.items()}

        return {
            "horizons": [{"label": h.label, "seconds": None if h.frozen else h.seconds, "delay": h.delay}
                         for h in self.horizons],
            "components": list(self.components),
            "rmse": self.rmse, "rmse_inside": self.rmse_inside, "rmse_outside": self.rmse_outside,
            "mean": means(self.rmse), "mean_inside": means(self.rmse_inside),
            "mean_outside": means(self.rmse_outside),
            "n_scored": self.n_scored, "n_inside": self.n_inside, "sample_period_s": self.sample_period_s,
            "slices": self.slices, "slice_share": self.slice_share,
        }


def _rmse(err: np.ndarray) -> list[float]:
    if err.shape[0] == 0:
        return [math.nan] * err.shape[1]
    return [float(v) for v in np.sqrt(np.mean(err ** 2, axis=0))]


def evaluate_horizons(models: Mapping[str, Any], train: SampleArrays, test: SampleArrays, *,
                      horizons: Sequence[float | str] = DEFAULT_HORIZONS, fixed: Sequence[str] = (),
                      components: Sequence[str] | None = None,
                      frozen_models: Mapping[str, Any] | None = None) -> HorizonReport:
    """Score trained models on a test stream at every horizon (see the module docstring).

    Args:
        models: Models *already trained* on ``train`` (not modified: each horizon runs a ``copy()``).
            Persistence belongs here too (trained: its last value is the training stream's last y).
        train: The training stream (for the range split).
        test: The test stream.
        horizons: Horizons [s] (0 = one step) and/or :data:`FROZEN`.
        fixed: Names of models that never learn (CAD, a batch fit): predicted once, the same at every
            horizon.
        components: Output names (default ``y0``, ``y1``, …).
        frozen_models: Per model name, what predicts at the frozen horizon instead of the model itself
            (e.g. the served model, learned by the node's estimator and loaded from its checkpoint:
            :class:`~semiparam_ros.eval.models.served.ServedModel`); it is not trained further.

    Returns:
        The :class:`HorizonReport`.

    Raises:
        ConfigurationError: If no horizon fits in the test stream (the largest delay must leave at least
            a quarter of it to score), or ``fixed`` names an absent model.
    """
    absent = [k for k in fixed if k not in models]
    if absent:
        raise ConfigurationError(f"fixed names models that are not evaluated: {absent}")
    period = test.sample_period_s
    n = len(test)
    hs = [h for h in parse_horizons(horizons, period) if h.delay <= 0.75 * n]
    if not hs:
        raise ConfigurationError(f"no horizon fits in a test stream of {n} samples ({n * period:.1f} s)")
    start = max(h.delay for h in hs)
    names = tuple(components) if components is not None else tuple(f"y{k}" for k in range(test.n_outputs))
    inside = inside_training_range(train.X, test.X)[start:]
    masks = motion_slices(test.X[start:], test.X.shape[1] // 3, test.n_outputs, period)
    sliced: dict[str, dict[str, dict[str, float]]] = {}
    rm_all: dict[str, dict[str, list[float]]] = {}
    rm_in: dict[str, dict[str, list[float]]] = {}
    rm_out: dict[str, dict[str, list[float]]] = {}
    for name, model in models.items():
        rm_all[name], rm_in[name], rm_out[name], sliced[name] = {}, {}, {}, {}
        fixed_pred = None
        for h in hs:
            if name in fixed:
                if fixed_pred is None:
                    fixed_pred = delayed_predictions(model, test.X, test.Y, 0)
                pred = fixed_pred
            elif h.frozen and frozen_models is not None and name in frozen_models:
                pred = delayed_predictions(frozen_models[name], test.X, test.Y, 0)
            else:
                pred = delayed_predictions(model.copy(), test.X, test.Y, h.delay, test.stamps_ns)
            err = (pred - test.Y)[start:]
            rm_all[name][h.label] = _rmse(err)
            rm_in[name][h.label] = _rmse(err[inside])
            rm_out[name][h.label] = _rmse(err[~inside])
            sliced[name][h.label] = slice_rmse(err, masks)
    return HorizonReport(tuple(hs), names, rm_all, rm_in, rm_out, int(n - start), int(inside.sum()), period,
                         sliced, slice_shares(masks))


#: Horizons of the headline: what a controller is served (frozen) beside one step ahead.
HEADLINE_HORIZONS: tuple[float | str, ...] = (0.0, FROZEN)


def horizon_markdown(report: HorizonReport, *, reference: str | None = "persistence") -> str:
    """Render the mean RMSE of every model at every horizon (all, inside and outside the training range).

    Args:
        report: A :class:`HorizonReport`.
        reference: Model whose row the ratios of the last table divide by (None: no ratio table).

    Returns:
        Markdown.
    """
    labels = [h.label for h in report.horizons]
    head = "| model | " + " | ".join(labels) + " |\n|---" + "|---" * len(labels) + "|\n"

    def table(subset: str) -> str:
        return head + "".join(
            f"| {m} | " + " | ".join(f"{report.mean(m, h, subset):.3f}" for h in labels) + " |\n"
            for m in report.rmse)

    legend = ("h: learned every sample up to t − h, predicts t", "frozen: no test sample learned",
              "persistence held h: ŷ(t) = y(t − h)")
    text = (f"Scored samples: {report.n_scored} (from the largest delay on), " + f"{report.n_inside} inside "
            + f"the training range of q and q̇; period {report.sample_period_s * 1e3:.1f} ms. "
            + "Mean RMSE over the outputs by the age of the model (" + "; ".join(legend) + ").\n\n"
            + "All scored samples:\n\n" + table("all"))
    if report.n_inside:
        text += "\nInside the training range:\n\n" + table("inside")
    if report.n_inside < report.n_scored:
        text += "\nOutside the training range:\n\n" + table("outside")
    if reference is not None and reference in report.rmse:
        text += f"\nRatio to {reference} at the same horizon (all scored samples; < 1: better):\n\n" + head
        for m in report.rmse:
            ratios = []
            for h in labels:
                ref = report.mean(reference, h)
                ratios.append(f"{report.mean(m, h) / ref:.2f}" if ref > 0 else "n/a")
            text += f"| {m} | " + " | ".join(ratios) + " |\n"
    return text


def horizon_figure(report: HorizonReport, path: Any, *, title: str = "") -> None:
    """Plot mean RMSE against the model's age (log axis; frozen at the right end) and save it.

    Args:
        report: A :class:`HorizonReport`.
        path: Image file to write (PNG).
        title: Figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    finite = [h for h in report.horizons if not h.frozen]
    xs = [h.seconds for h in finite]
    frozen_x = (max(xs) * 10.0) if xs else 1.0
    fig, ax = plt.subplots(figsize=(7.0, 4.2))
    for m in report.rmse:
        pts = [(h.seconds if not h.frozen else frozen_x, report.mean(m, h.label)) for h in report.horizons]
        style = "--" if m == "persistence" else "-"
        ax.plot([p[0] for p in pts], [p[1] for p in pts], style, marker="o", label=m)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ticks = [*xs, frozen_x]
    ax.set_xticks(ticks)
    ax.set_xticklabels([h.label for h in finite] + [FROZEN])
    ax.set_xlabel("age of the model h (learned up to t − h)")
    ax.set_ylabel("mean RMSE over outputs")
    ax.set_title(title or "error by the age of the model")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        atomic_savefig(fig, path, dpi=110)
    finally:
        plt.close(fig)
