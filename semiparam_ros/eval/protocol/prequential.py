"""The paper's evaluation protocol on sample arrays and online models.

Camoriano et al. (ICRA 2016, Sec. IV-C): initialise the parametric (P), nonparametric (NP) and
semiparametric (SP) models at zero; train each on the whole training log (XY circles); split the test log
(XZ circles) into sequential parts; on each part, starting from a copy of the trained model, predict and
then update one sample at a time; report mean and standard deviation over the parts of the
component-averaged RMSE of forces and torques over a sliding window.

This module works on plain arrays (:class:`SampleArrays`) and on any
:class:`~semiparam_ros.core.learners.contract.OnlineModel` (``predict_learn_one(x, y)`` returning a
prediction with a ``total`` attribute or an array, and ``copy()``), so it is tested against hand-written
loops on toy models and used unchanged on bags by :mod:`semiparam_ros.eval.bags.replay`. What the outputs
are (a wrench or joint torques, hence the groups and units) is given by an
:class:`~semiparam_ros.eval.protocol.metrics.OutputSpec`.

A second protocol, :func:`run_adaptation`, follows one stream through an abrupt change (a payload picked
up at a known time) and measures how fast each model's error returns to its pre-change level.

Units: time in s (stamps in int ns), errors in N (forces) and N·m (torques), update times in µs.

The results are arrays (:class:`ProtocolResult`, :class:`AdaptationResult`); the typed report built once
from them is :func:`semiparam_ros.eval.protocol.report.protocol_report`.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from semiparam_ros.core.learners.contract import OnlineModel
from semiparam_ros.core.stream.rate import stream_period_s
from semiparam_ros.errors import ConfigurationError
from semiparam_ros.eval.protocol.metrics import (
    OutputSpec,
    component_rmse,
    group_rmse,
    window_samples,
    windowed_rmse,
)
from semiparam_ros.eval.protocol.options import DEFAULT_FIRST_S, DEFAULT_SPLITS, DEFAULT_WINDOW_S

__all__ = [
    "AdaptationResult",
    "ProtocolResult",
    "Recovery",
    "SampleArrays",
    "needs_stamps",
    "predict_only",
    "progress_enabled",
    "recovery",
    "run_adaptation",
    "run_protocol",
    "split_bounds",
    "stamps_for",
    "test_then_train",
    "train",
]

_NS = 1e-9


Progress = Callable[[int], None]


def _total(prediction: Any) -> np.ndarray:
    return np.asarray(getattr(prediction, "total", prediction), dtype=np.float64).reshape(-1)


@dataclass(frozen=True)
class SampleArrays:
    """A stream of learning samples as arrays.

    Attributes:
        stamps_ns: Sample stamps [ns], shape ``(n,)``, strictly increasing.
        X: Inputs ``[q, dq, ddq]`` (rad, rad/s, rad/s²), shape ``(n, d)``.
        Y: Measured outputs (wrench ``[fx, fy, fz, tx, ty, tz]`` in N, N·m, or joint torques), ``(n, t)``.
        Y_true: Noise-free outputs at the same stamps when known (simulated bags), else ``None``.
    """

    stamps_ns: np.ndarray
    X: np.ndarray
    Y: np.ndarray
    Y_true: np.ndarray | None = None

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_ns, dtype=np.int64).reshape(-1)
        X = np.asarray(self.X, dtype=np.float64)
        Y = np.asarray(self.Y, dtype=np.float64)
        if X.ndim != 2 or Y.ndim != 2:
            raise ValueError(f"X and Y must be 2-D, got shapes {X.shape} and {Y.shape}")
        if not (len(stamps) == X.shape[0] == Y.shape[0]):
            raise ValueError(f"stamps, X and Y disagree in length: {len(stamps)}, {X.shape[0]}, {Y.shape[0]}")
        if len(stamps) > 1 and np.any(np.diff(stamps) <= 0):
            raise ValueError("sample stamps must be strictly increasing")
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Y))):
            raise ValueError("X or Y contain NaN or inf")
        Y_true = None
        if self.Y_true is not None:
            Y_true = np.asarray(self.Y_true, dtype=np.float64)
            if Y_true.shape != Y.shape or not np.all(np.isfinite(Y_true)):
                raise ValueError(f"Y_true must be finite with the shape of Y {Y.shape}, got {Y_true.shape}")
        object.__setattr__(self, "stamps_ns", stamps)
        object.__setattr__(self, "X", X)
        object.__setattr__(self, "Y", Y)
        object.__setattr__(self, "Y_true", Y_true)

    @classmethod
    def from_samples(cls, samples: Iterable[Any], ground_truth: Mapping[int, np.ndarray] | None = None,
                     limit: int | None = None) -> SampleArrays:
        """Collect :class:`~semiparam_ros.core.stream.messages.Sample` objects into arrays.

        Args:
            samples: Objects with ``stamp_ns``, ``x`` and ``y``.
            ground_truth: Noise-free outputs by stamp [ns]; used only if every sample has one.
            limit: Keep at most this many samples (the first ones).

        Returns:
            The arrays.

        Raises:
            ValueError: If no sample is given or samples are malformed.
        """
        stamps, xs, ys = [], [], []
        for sample in samples:
            if limit is not None and len(stamps) >= limit:
                break
            stamps.append(int(sample.stamp_ns))
            xs.append(np.asarray(sample.x, dtype=np.float64))
            ys.append(np.asarray(sample.y, dtype=np.float64))
        if not stamps:
            raise ValueError("no samples")
        y_true = None
        if ground_truth and all(s in ground_truth for s in stamps):
            y_true = np.stack([np.asarray(ground_truth[s], dtype=np.float64) for s in stamps])
        return cls(np.array(stamps, dtype=np.int64), np.stack(xs), np.stack(ys), y_true)

    def __len__(self) -> int:
        return len(self.stamps_ns)

    @property
    def n_outputs(self) -> int:
        """Number of output components t."""
        return self.Y.shape[1]

    @property
    def sample_period_s(self) -> float:
        """The stream's period [s] as the node measures it (:func:`.rate.measured_period_s`).

        For a stream too short for that, its median stamp difference (``nan`` for a single sample).
        """
        period = stream_period_s(self.stamps_ns)
        return float("nan") if period is None else period

    @property
    def duration_s(self) -> float:
        """Time from the first to the last stamp [s]."""
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) * _NS

    def slice(self, start: int, stop: int) -> SampleArrays:
        """Return samples ``start:stop``."""
        return SampleArrays(self.stamps_ns[start:stop], self.X[start:stop], self.Y[start:stop],
                            None if self.Y_true is None else self.Y_true[start:stop])

    def head(self, n: int | None) -> SampleArrays:
        """Return the first ``n`` samples (all when ``n`` is ``None``)."""
        return self if n is None else self.slice(0, n)


def split_bounds(n_samples: int, splits: int, split_size: int | None = None) -> list[tuple[int, int]]:
    """Sequential, non-overlapping parts of a test stream.

    Args:
        n_samples: Length of the test stream.
        splits: Number of parts (>= 1).
        split_size: Samples per part; ``None`` divides the stream into ``splits`` equal parts
            (``n_samples // splits`` each, the remainder at the end unused).

    Returns:
        ``[(start, stop), ...]`` index ranges of the parts, in order.

    Raises:
        ValueError: If the stream is too short for the request or an argument is invalid.
    """
    if splits < 1:
        raise ValueError(f"splits must be >= 1, got {splits}")
    if split_size is None:
        split_size = n_samples // splits
        if split_size < 2:
            raise ValueError(f"{n_samples} test samples cannot be divided into {splits} parts of >= 2 "
                             "samples")
    elif split_size < 2:
        raise ValueError(f"split_size must be >= 2, got {split_size}")
    if splits * split_size > n_samples:
        raise ValueError(f"the test stream has {n_samples} samples, fewer than splits x split_size = "
                         f"{splits} x {split_size}; lower --splits/--split-size or omit --split-size")
    return [(k * split_size, (k + 1) * split_size) for k in range(splits)]


def train(model: OnlineModel, data: SampleArrays, progress: Progress | None = None) -> np.ndarray:
    """Train a model on a whole stream, one sample at a time (predict, then learn — as online).

    Args:
        model: The model, updated in place.
        data: Training samples.
        progress: Called with the number of samples processed since the last call.

    Returns:
        The a-priori predictions during training, shape ``(n, t)``.
    """
    return test_then_train(model, data.X, data.Y, progress, data.stamps_ns)[0]


def needs_stamps(model: Any) -> bool:
    """Whether a model learns with the samples' stamps (``needs_stamps``: the node's estimator)."""
    return bool(getattr(model, "needs_stamps", False))


def stamps_for(model: Any, stamps_ns: np.ndarray | None, n: int) -> np.ndarray | None:
    """Return the stamps to give a model with each of n samples: ``stamps_ns`` if it :func:`needs_stamps`.

    Returns:
        ``stamps_ns``, or None for a model that learns without stamps.

    Raises:
        ConfigurationError: A model that needs stamps without one per sample.
    """
    if not needs_stamps(model):
        return None
    if stamps_ns is None or len(stamps_ns) != n:
        raise ConfigurationError("this model learns with the samples' stamps: pass stamps_ns, one per sample")
    return stamps_ns


def test_then_train(model: OnlineModel, X: np.ndarray, Y: np.ndarray,
                    progress: Progress | None = None,
                    stamps_ns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predict each sample before learning it (the paper's test-and-update), one at a time.

    Args:
        model: The model, updated in place.
        X: Inputs, shape ``(n, d)``.
        Y: Targets, shape ``(n, t)``.
        progress: Called with the number of samples processed since the last call (every 100).
        stamps_ns: The samples' stamps [ns], passed as ``stamp_ns=`` to a model that
            :func:`needs_stamps` (required for it).

    Returns:
        ``(predictions (n, t), update_ns (n,))``: the a-priori predictions and the wall time of each
        ``predict_learn_one`` call [ns].

    Raises:
        ConfigurationError: A model that needs stamps without one per sample.
    """
    n = X.shape[0]
    predictions = np.empty_like(Y, dtype=np.float64)
    update_ns = np.empty(n, dtype=np.int64)
    clock = time.perf_counter_ns
    stamps = stamps_for(model, stamps_ns, n)
    for i in range(n):
        t0 = clock()
        if stamps is None:
            prediction = model.predict_learn_one(X[i], Y[i])
        else:
            prediction = model.predict_learn_one(X[i], Y[i], stamp_ns=int(stamps[i]))
        update_ns[i] = clock() - t0
        predictions[i] = _total(prediction)
        if progress is not None and (i + 1) % 100 == 0:
            progress(100)
    if progress is not None and n % 100:
        progress(n % 100)
    return predictions, update_ns


def predict_only(model: Any, X: np.ndarray,
                 progress: Progress | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predict each sample without learning it (a model frozen after training: generalization).

    Args:
        model: A trained model with ``predict_one(x)`` (array or object with ``.total``), or
            ``predict_model(x)`` which is then used (the model without its fast correction); not modified.
        X: Inputs, shape ``(n, d)``.
        progress: Called with the number of samples processed since the last call (every 100).

    Returns:
        ``(predictions (n, t), predict_ns (n,))``: the predictions and the wall time of each call [ns].

    Raises:
        TypeError: If the model has no ``predict_one``.
    """
    # a frozen learner is used as its model (without the fast correction of its last errors, if it has one)
    predict = getattr(model, "predict_model", None) or getattr(model, "predict_one", None)
    if not callable(predict):
        raise TypeError(f"{type(model).__name__} has no predict_one: it cannot be evaluated frozen")
    n = X.shape[0]
    rows: list[np.ndarray] = []
    predict_ns = np.empty(n, dtype=np.int64)
    clock = time.perf_counter_ns
    for i in range(n):
        t0 = clock()
        prediction = predict(X[i])
        predict_ns[i] = clock() - t0
        rows.append(_total(prediction))
        if progress is not None and (i + 1) % 100 == 0:
            progress(100)
    if progress is not None and n % 100:
        progress(n % 100)
    return np.stack(rows) if rows else np.empty((0, 0)), predict_ns


@dataclass
class ProtocolResult:
    """Everything the paper's protocol produces (see :func:`run_protocol`).

    Attributes:
        kinds: Model names in order (e.g. ``("P", "NP", "SP")``).
        bounds: ``(start, stop)`` of each test split.
        predictions: Per model, a-priori test predictions, shape ``(splits, split_size, t)``.
        targets: Measured test outputs, shape ``(splits, split_size, t)``.
        targets_true: Noise-free test outputs (same shape) or ``None``.
        time_s: Elapsed time of each split sample from the split's start, plus one period [s], shape
            ``(split_size,)`` (median over splits; > 0 so that it fits a log axis).
        sample_period_s: Median sample period of the test stream [s].
        window: Sliding-window length [samples].
        first: Samples making up the "first seconds" segment.
        first_s: Length of that segment [s].
        update_ns: Per model, wall time of each test ``predict_learn_one`` [ns], ``(splits, split_size)``.
        train_ns: Per model, total training wall time [ns].
        samples_train: Number of training samples.
        first_s: Length of the initial segment [s].
        output: What the outputs are (groups, components, units).
        stamps_ns: Stamp of every test sample [ns], ``(splits, split_size)``.
    """

    kinds: tuple[str, ...]
    bounds: list[tuple[int, int]]
    predictions: dict[str, np.ndarray]
    targets: np.ndarray
    targets_true: np.ndarray | None
    time_s: np.ndarray
    sample_period_s: float
    window: int
    first: int
    update_ns: dict[str, np.ndarray]
    train_ns: dict[str, int]
    samples_train: int
    first_s: float
    output: OutputSpec
    stamps_ns: np.ndarray | None = None

    @classmethod
    def merge(cls, parts: Sequence[ProtocolResult]) -> ProtocolResult:
        """One result of the models of several runs on the same streams (e.g. one model per job).

        Raises:
            ValueError: If the runs' test splits differ or a model name repeats.
        """
        first = parts[0]
        kinds = tuple(k for p in parts for k in p.kinds)
        if any(p.bounds != first.bounds for p in parts) or len(set(kinds)) != len(kinds):
            raise ValueError("results merged must share their test splits and name each model once")
        return replace(first, kinds=kinds,
                       predictions={k: p.predictions[k] for p in parts for k in p.kinds},
                       update_ns={k: p.update_ns[k] for p in parts for k in p.kinds},
                       train_ns={k: p.train_ns[k] for p in parts for k in p.kinds})

    @property
    def samples_test(self) -> int:
        """Number of test samples used (splits × split size)."""
        return int(self.targets.shape[0] * self.targets.shape[1])

    def errors(self, kind: str, truth: bool = False) -> np.ndarray:
        """Prediction errors ``ŷ - y`` of a model, shape ``(splits, split_size, t)``.

        Args:
            kind: Model name.
            truth: Against the noise-free outputs instead of the measured ones.

        Raises:
            ValueError: If ``truth`` is requested but the stream has no noise-free outputs.
        """
        if truth:
            if self.targets_true is None:
                raise ValueError("the test stream has no noise-free outputs")
            return self.predictions[kind] - self.targets_true
        return self.predictions[kind] - self.targets

    def _columns(self, group: str) -> list[int]:
        return list(self.output.groups[group].columns)

    def segment(self, segment: str) -> slice:
        """Sample range of a segment within each split.

        Args:
            segment: ``"regime"`` (second half of each split) or ``"first"`` (the first ``first_s``).

        Raises:
            ValueError: On another name.
        """
        length = self.targets.shape[1]
        if segment == "regime":
            return slice(length // 2, length)
        if segment == "first":
            return slice(0, self.first)
        raise ValueError(f"segment must be 'regime' or 'first', got {segment!r}")

    def curves(self, kind: str, group: str, truth: bool = False) -> np.ndarray:
        """Windowed component-averaged RMSE of each split, shape ``(splits, split_size)``."""
        err = self.errors(kind, truth)[:, :, self._columns(group)]
        return np.stack([windowed_rmse(e, self.window) for e in err])

    def segment_rmse(self, kind: str, group: str, segment: str, truth: bool = False) -> np.ndarray:
        """Component-averaged RMSE of each split over a segment, shape ``(splits,)``.

        Args:
            kind: Model name.
            group: A group of :attr:`output` (``"force"`` or ``"torque"``).
            segment: ``"regime"`` (second half of each split) or ``"first"`` (first seconds).
            truth: Against the noise-free outputs.
        """
        err = self.errors(kind, truth)[:, self.segment(segment)][:, :, self._columns(group)]
        return np.array([group_rmse(e) for e in err])

    def component_rmse(self, kind: str, segment: str, truth: bool = False) -> np.ndarray:
        """RMSE of every output component in each split over a segment, shape ``(splits, t)``."""
        err = self.errors(kind, truth)[:, self.segment(segment)]
        return np.stack([component_rmse(e) for e in err])

    def component_nmse(self, kind: str, segment: str, truth: bool = False) -> np.ndarray:
        """Return the normalized MSE of each output component over a segment, pooled over splits, ``(t,)``.

        ``nMSE_c = mean(e_c²) / var(y_c)`` over the segment's samples of all splits, with ``y`` the measured
        output (also when ``truth``: the normalization is the signal's spread, not the reference's). A
        component with zero measured variance gets ``inf`` (or ``nan`` with zero error).
        """
        part = self.segment(segment)
        err = self.errors(kind, truth)[:, part].reshape(-1, self.targets.shape[2])
        var = np.var(self.targets[:, part].reshape(-1, self.targets.shape[2]), axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.mean(err * err, axis=0) / var


def run_protocol(models: Mapping[str, OnlineModel], train_data: SampleArrays, test_data: SampleArrays, *,
                 output: OutputSpec, splits: int = DEFAULT_SPLITS, split_size: int | None = None,
                 window_s: float = DEFAULT_WINDOW_S, first_s: float = DEFAULT_FIRST_S,
                 progress: bool | Progress = False,
                 frozen: Collection[str] = (), trained: Collection[str] = ()) -> ProtocolResult:
    """Run the paper's protocol: train every model on the whole train stream, then test-and-update.

    Each model is trained in place on all of ``train_data`` (one sample at a time); then for every split of
    ``test_data`` an independent ``copy()`` of the trained model predicts and learns each sample in turn.
    The models take turns every :data:`INTERLEAVE` samples (the same numbers as one after the other: each
    has its own state), so that a machine's load falls on all of them alike and their update times
    compare.
    Models named in ``frozen`` only predict the test parts (:func:`predict_only`, no updates): what the
    trained model generalizes to, as used without online learning.

    Args:
        models: Fresh models by name (the paper: P, NP, SP with zero parameters). Trained in place.
        train_data: Training stream (the XY log).
        test_data: Test stream (the XZ log).
        output: What the outputs are (``OutputSpec.from_config(config)``): groups and units of the report.
        splits: Number of sequential test parts.
        split_size: Samples per part; ``None`` = equal parts.
        window_s: Sliding-window length [s], converted to samples at the test stream's sample rate.
        first_s: Length of the initial segment reported separately [s] (``*_first_<first_s>s`` in the JSON).
        progress: ``True`` for a progress bar on stderr (shown only when stderr is a terminal), or a
            callable receiving processed-sample counts.
        frozen: Names of ``models`` evaluated without test updates (``update_ns`` then holds the
            prediction times).
        trained: Names of ``models`` already fitted to ``train_data`` (e.g. by a batch fit): not trained
            again (their ``train_ns`` is 0).

    Returns:
        The :class:`ProtocolResult`.

    Raises:
        ValueError: If no model is given, ``frozen`` or ``trained`` names an absent model, the streams
            disagree in output size or with ``output``, or the test stream is too short for the split
            request.
    """
    if not models:
        raise ValueError("no models to evaluate")
    absent = [k for k in (*frozen, *trained) if k not in models]
    if absent:
        raise ValueError(f"frozen or trained names models that are not evaluated: {absent}")
    if train_data.n_outputs != test_data.n_outputs or train_data.X.shape[1] != test_data.X.shape[1]:
        raise ValueError("train and test streams differ in input or output size")
    output.check(test_data.n_outputs)
    bounds = split_bounds(len(test_data), splits, split_size)
    length = bounds[0][1] - bounds[0][0]
    period = test_data.sample_period_s
    window = window_samples(window_s, period)
    first = min(length, window_samples(first_s, period))
    kinds = tuple(models)
    total = len(kinds) * (len(train_data) + len(bounds) * length)
    bar, tick = _progress(progress, total)
    # The models take turns every INTERLEAVE samples (each on its own state, so the numbers are those of
    # one model after the other): a machine's load then falls on all of them alike, and their update
    # times compare.
    try:
        train_ns = dict.fromkeys(kinds, 0)
        for start in range(0, len(train_data), INTERLEAVE):
            stop = min(start + INTERLEAVE, len(train_data))
            for kind, model in models.items():
                if kind in trained:
                    continue
                t0 = time.perf_counter_ns()
                test_then_train(model, train_data.X[start:stop], train_data.Y[start:stop], tick,
                                train_data.stamps_ns[start:stop])
                train_ns[kind] += time.perf_counter_ns() - t0
        if tick is not None:
            for _ in trained:
                tick(len(train_data))
        preds: dict[str, list[np.ndarray]] = {k: [] for k in kinds}
        times: dict[str, list[np.ndarray]] = {k: [] for k in kinds}
        for start, stop in bounds:
            # a frozen model predicts with the trained one; the others learn an independent copy per part
            part = {k: m if k in frozen else m.copy() for k, m in models.items()}
            blocks: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {k: [] for k in kinds}
            for a in range(start, stop, INTERLEAVE):
                b = min(a + INTERLEAVE, stop)
                for kind, model in part.items():
                    if kind in frozen:
                        blocks[kind].append(predict_only(model, test_data.X[a:b], tick))
                    else:
                        blocks[kind].append(test_then_train(model, test_data.X[a:b], test_data.Y[a:b], tick,
                                                            test_data.stamps_ns[a:b]))
            for kind in kinds:
                preds[kind].append(np.concatenate([p for p, _ in blocks[kind]]))
                times[kind].append(np.concatenate([t for _, t in blocks[kind]]))
        predictions = {k: np.stack(preds[k]) for k in kinds}
        update_ns = {k: np.stack(times[k]) for k in kinds}
    finally:
        if bar is not None:
            bar.close()
    targets = np.stack([test_data.Y[a:b] for a, b in bounds])
    targets_true = None if test_data.Y_true is None else np.stack([test_data.Y_true[a:b] for a, b in bounds])
    elapsed = np.stack([test_data.stamps_ns[a:b] - test_data.stamps_ns[a] for a, b in bounds]) * _NS
    time_s = np.median(elapsed, axis=0) + period
    return ProtocolResult(kinds=kinds, bounds=bounds, predictions=predictions, targets=targets,
                          targets_true=targets_true, time_s=time_s, sample_period_s=period, window=window,
                          first=first, first_s=first_s, update_ns=update_ns, train_ns=train_ns,
                          samples_train=len(train_data), output=output,
                          stamps_ns=np.stack([test_data.stamps_ns[a:b] for a, b in bounds]))


#: Samples each model runs before the next takes its turn in :func:`run_protocol`.
INTERLEAVE = 250


def progress_enabled(requested: bool) -> bool:
    """Whether to draw a progress bar: only when asked for and stderr is a terminal.

    A bar redrawn with carriage returns into a log file or a pipe leaves thousands of frames in it.
    """
    return bool(requested) and sys.stderr.isatty()


def _progress(progress: bool | Progress, total: int) -> tuple[Any, Progress | None]:
    if progress is True:
        if not progress_enabled(True):
            return None, None
        from tqdm import tqdm

        bar = tqdm(total=total, unit="sample", dynamic_ncols=True, smoothing=0.05)
        return bar, bar.update
    if callable(progress):
        return None, progress
    return None, None


@dataclass
class AdaptationResult:
    """One stream through an abrupt change, per model (see :func:`run_adaptation`).

    Attributes:
        kinds: Model names.
        time_s: Sample times relative to the change [s], shape ``(n,)`` (negative before it).
        errors: Per model, a-priori errors ``ŷ - y``, shape ``(n, t)``.
        errors_true: Per model, errors against the noise-free outputs, or ``None``.
        window: Sliding-window length [samples].
        curves: Per model and group, windowed component-averaged RMSE, shape ``(n,)``.
        summary: Per model and group, the :class:`Recovery`.
        change_s: Time of the change from the stream's first stamp [s].
        tolerance: Recovery tolerance (ratio to the pre-change level).
        deadline_s: Recovery deadline after the change [s].
        pre_s: Length of the pre-change reference segment [s].
    """

    kinds: tuple[str, ...]
    time_s: np.ndarray
    errors: dict[str, np.ndarray]
    errors_true: dict[str, np.ndarray] | None
    window: int
    curves: dict[str, dict[str, np.ndarray]]
    summary: dict[str, dict[str, Recovery]]
    change_s: float
    tolerance: float
    deadline_s: float
    pre_s: float
    output: OutputSpec


@dataclass(frozen=True)
class Recovery:
    """How one model's error in one group went through the change (errors in N or N·m, times in s).

    Attributes:
        pre_rmse: Component-averaged RMSE over ``pre_s`` before the change.
        peak: Largest windowed RMSE after the change.
        recovery_time_s: First time after the change from which the windowed RMSE stays within
            ``tolerance × pre_rmse`` to the end of the stream; ``None`` if never.
        level_at_deadline: Windowed RMSE at ``deadline_s`` after the change.
        ratio_at_deadline: ``level_at_deadline / pre_rmse``.
        post_rmse: Component-averaged RMSE from ``deadline_s`` to the end (``nan`` if no sample).
        recovered: ``recovery_time_s <= deadline_s``.
    """

    pre_rmse: float
    peak: float
    recovery_time_s: float | None
    level_at_deadline: float
    ratio_at_deadline: float
    post_rmse: float
    recovered: bool


def run_adaptation(models: Mapping[str, OnlineModel], stream: SampleArrays, change_s: float, *,
                   output: OutputSpec, pretrain: SampleArrays | None = None,
                   window_s: float = DEFAULT_WINDOW_S,
                   pre_s: float = 10.0, deadline_s: float = 10.0, tolerance: float = 1.5,
                   progress: bool | Progress = False) -> AdaptationResult:
    """Follow a stream through an abrupt change (e.g. a payload picked up) with test-then-train.

    Each model is optionally trained on ``pretrain`` first, then predicts and learns every sample of
    ``stream``. The pre-change level of a group is its component-averaged RMSE over ``[change - pre_s,
    change)``; the model has recovered if its windowed RMSE is within ``tolerance ×`` that level from some
    time ``<= change + deadline_s`` to the end of the stream.

    Args:
        models: Models by name (e.g. ``{"SP adaptive": ..., "SP": ...}``), updated in place.
        stream: The stream containing the change.
        change_s: Time of the change from the stream's first stamp [s].
        output: What the outputs are (groups and units).
        pretrain: Optional stream each model learns first.
        window_s: Sliding-window length [s].
        pre_s: Length of the pre-change reference segment [s].
        deadline_s: Recovery deadline after the change [s].
        tolerance: Allowed ratio to the pre-change level.
        progress: As in :func:`run_protocol`.

    Returns:
        The :class:`AdaptationResult`.

    Raises:
        ValueError: If the change is not inside the stream with ``pre_s`` of data before it.
    """
    if not models:
        raise ValueError("no models to evaluate")
    output.check(stream.n_outputs)
    t = (stream.stamps_ns - stream.stamps_ns[0]) * _NS - change_s
    if not (t[0] <= -pre_s + 1e-9 and t[-1] > 0):
        raise ValueError(f"the change at {change_s:g} s needs {pre_s:g} s of data before it and some after "
                         "it "
                         f"in a stream of {stream.duration_s:.3g} s")
    window = window_samples(window_s, stream.sample_period_s)
    total = len(models) * (len(stream) + (0 if pretrain is None else len(pretrain)))
    bar, tick = _progress(progress, total)
    errors: dict[str, np.ndarray] = {}
    try:
        for kind, model in models.items():
            if pretrain is not None:
                train(model, pretrain, tick)
            pred, _ = test_then_train(model, stream.X, stream.Y, tick)
            errors[kind] = pred - stream.Y
    finally:
        if bar is not None:
            bar.close()
    errors_true = None
    if stream.Y_true is not None:
        errors_true = {k: e + stream.Y - stream.Y_true for k, e in errors.items()}
    groups = {name: list(g.columns) for name, g in output.groups.items()}
    pre = (t >= -pre_s) & (t < 0)
    after = t >= 0
    curves: dict[str, dict[str, np.ndarray]] = {}
    summary: dict[str, dict[str, Recovery]] = {}
    for kind, err in errors.items():
        curves[kind], summary[kind] = {}, {}
        for group, cols in groups.items():
            curve = windowed_rmse(err[:, cols], window)
            curves[kind][group] = curve
            pre_rmse = group_rmse(err[pre][:, cols])
            summary[kind][group] = recovery(t, curve, err[:, cols], pre_rmse, after, tolerance, deadline_s)
    return AdaptationResult(kinds=tuple(models), time_s=t, errors=errors, errors_true=errors_true,
                            window=window, curves=curves, summary=summary, change_s=change_s,
                            tolerance=tolerance, deadline_s=deadline_s, pre_s=pre_s, output=output)


def recovery(t: np.ndarray, curve: np.ndarray, err: np.ndarray, pre_rmse: float, after: np.ndarray,
             tolerance: float, deadline_s: float) -> Recovery:
    """How a windowed error went through a change at ``t = 0`` (the definition of :func:`run_adaptation`).

    Args:
        t: (n,) times from the change [s].
        curve: (n,) sliding-window RMSE of the group [N or N·m].
        err: (n, c) errors of the group's components [N or N·m].
        pre_rmse: The pre-change level [N or N·m].
        after: (n,) mask of the samples from the change on.
        tolerance: Recovered when the curve stays within ``tolerance × pre_rmse``.
        deadline_s: Deadline after the change [s].

    Returns:
        The :class:`Recovery` (``recovery_time_s``: first time from which the curve stays within the bound
        to the end; ``None`` if never).
    """
    limit = tolerance * pre_rmse
    idx_after = np.flatnonzero(after)
    bad_after = idx_after[curve[idx_after] > limit]
    if bad_after.size == 0:
        recovery = 0.0
    elif bad_after[-1] == len(t) - 1:
        recovery = None
    else:
        recovery = float(t[bad_after[-1] + 1])
    at_deadline = int(np.searchsorted(t, deadline_s, side="right")) - 1
    post = t >= deadline_s
    level = float(curve[at_deadline]) if at_deadline >= 0 else float("nan")
    return Recovery(pre_rmse=pre_rmse, peak=float(np.max(curve[idx_after])), recovery_time_s=recovery,
                    level_at_deadline=level,
                    ratio_at_deadline=level / pre_rmse if pre_rmse > 0 else float("inf"),
                    post_rmse=group_rmse(err[post]) if np.any(post) else float("nan"),
                    recovered=recovery is not None and recovery <= deadline_s)

