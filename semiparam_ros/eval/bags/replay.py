"""Bag replay: read bags through the node's own pipeline and run the evaluation protocols on them.

Samples come from exactly the objects the live node uses:
:func:`~semiparam_ros.core.estimator.build.build_pipeline`
(joint mapping, stamp pairing, acceleration estimate, drops counted) fed by
:func:`~semiparam_ros.io.bags.iter_samples`, and the learners of
:func:`~semiparam_ros.core.estimator.build.build_model`. When the bag also holds the noise-free wrench of a
simulation (``/ground_truth/wrench``), the noise-free wrench with the stamp of each sample (samples carry
the wrench stamp) is its noise-free output, so errors can be split into model error and sensor noise.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.build import build_model, build_pipeline, build_regressor
from semiparam_ros.core.kinds import OutputKind
from semiparam_ros.core.stream.rate import measured_period_s
from semiparam_ros.eval.models.frozen import FrozenParametricSP
from semiparam_ros.eval.protocol.horizon import HorizonReport, evaluate_horizons
from semiparam_ros.eval.protocol.metrics import OutputSpec
from semiparam_ros.eval.protocol.options import (
    CASCADE_SP,
    DEFAULT_WINDOW_S,
    JOINT_SP,
    ProtocolOptions,
    Variant,
)
from semiparam_ros.eval.protocol.prequential import (
    AdaptationResult,
    ProtocolResult,
    SampleArrays,
    run_adaptation,
    run_protocol,
)
from semiparam_ros.io.bags import absolute_topic, iter_samples, read_messages, topic_info
from semiparam_ros.jobs.parallel import run_jobs

__all__ = [
    "CASCADE_SP",
    "EXTRA_KINDS",
    "FROZEN_P",
    "GROUND_TRUTH_WRENCH_TOPIC",
    "JOINT_SP",
    "KINDS",
    "Topics",
    "adaptation_configs",
    "build_models",
    "evaluate_adaptation",
    "evaluate_bags",
    "load_samples",
    "payload_pickup",
    "read_change_time",
    "read_scenario",
]

#: Topic of the noise-free wrench written by the simulator (absent in real logs).
GROUND_TRUTH_WRENCH_TOPIC = "/ground_truth/wrench"
#: With a sample limit, ground-truth messages are read until their stamp passes the last sample's by this.
_TRUTH_MARGIN_NS = 1_000_000_000
#: The paper's three learners.
KINDS: tuple[str, ...] = ("P", "NP", "SP")
#: Diagnostic variant (:class:`~semiparam_ros.eval.models.frozen.FrozenParametricSP`): SP whose rigid-body
#: stage stops learning after the training stream.
FROZEN_P = "SPfrozenP"
#: Kinds :func:`build_models` accepts besides :data:`KINDS`.
EXTRA_KINDS: tuple[str, ...] = (JOINT_SP, CASCADE_SP, FROZEN_P)


@dataclass(frozen=True)
class Topics:
    """Bag topics to read.

    Attributes:
        joint_states: ``sensor_msgs/msg/JointState`` topic.
        wrench: ``geometry_msgs/msg/WrenchStamped`` topic (measured).
        ground_truth: Noise-free wrench topic; used when present in the bag, ``None`` to ignore.
    """

    joint_states: str = "/joint_states"
    wrench: str = "/wrench"
    ground_truth: str | None = GROUND_TRUTH_WRENCH_TOPIC

    @classmethod
    def from_config(cls, config: EstimatorConfig, joint_states: str | None = None,
                    wrench: str | None = None) -> Topics:
        """Topics from the configuration (``topics.*``, made absolute), optionally overridden."""
        return cls(joint_states=absolute_topic(joint_states or config["topics.joint_states"]),
                   wrench=absolute_topic(wrench or config["topics.wrench"]))


def load_samples(path: str | Path, config: EstimatorConfig, topics: Topics | None = None, *,
                 limit: int | None = None) -> tuple[SampleArrays, dict[str, int]]:
    """Read a bag through the node's pipeline into arrays.

    Args:
        path: Bag folder or ``.mcap`` file.
        config: Estimator configuration (joints, output, pairing, acceleration).
        topics: Topics to read; default from the configuration.
        limit: Keep only the first ``limit`` samples (a prefix, for quick runs).

    Returns:
        ``(samples, drops)``: the arrays (with noise-free outputs when the bag has them and the output is a
        wrench) and the pipeline's drop counts by reason.

    Raises:
        ValueError: If the bag cannot be read or yields no sample (BagError is a ValueError).
    """
    topics = topics or Topics.from_config(config)
    pipeline = build_pipeline(config)
    kwargs: dict[str, Any] = {"joint_states_topic": topics.joint_states}
    kwargs["wrench_topic"] = topics.wrench if config.output_kind == OutputKind.WRENCH else None
    samples: Iterable[Any] = iter_samples(path, pipeline, **kwargs)
    last_stamp = None
    if limit is not None:
        # a prefix: stop decoding the bag (and its ground truth, below) once it is complete
        samples = list(itertools.islice(samples, max(int(limit), 0)))
        last_stamp = max((s.stamp_ns for s in samples), default=None)
    truth: dict[int, np.ndarray] | None = None
    wrench = config.output_kind == OutputKind.WRENCH
    if wrench and topics.ground_truth and topics.ground_truth in topic_info(path):
        # samples carry the wrench stamp: the noise-free wrench of the same stamp is the exact target
        truth = {}
        for m in read_messages(path, joint_states_topic=None, wrench_topic=topics.ground_truth):
            if last_stamp is not None and m.stamp_ns > last_stamp + _TRUTH_MARGIN_NS:
                break  # log-time order follows the stamps up to the margin
            truth[m.stamp_ns] = m.wrench
    try:
        arrays = SampleArrays.from_samples(samples, truth, limit=limit)
    except ValueError as err:
        drops = {k: v for k, v in pipeline.drops.items() if v}
        if drops.get("missing_joint"):
            raise ValueError(f"{path}: {_missing_joints(path, topics.joint_states, config)}") from err
        raise ValueError(f"{path}: no usable samples on {topics.joint_states} + {topics.wrench} "
                         f"(drops: {drops}): {err}") from err
    return arrays, dict(pipeline.drops)


def _missing_joints(path: str | Path, topic: str, config: EstimatorConfig) -> str:
    """Say which configured joints the bag's joint states lack, and which names they have."""
    first = next(iter(read_messages(path, joint_states_topic=topic, wrench_topic=None)), None)
    names = [] if first is None else list(first.names)  # type: ignore[union-attr]
    missing = [j for j in config["robot.joints"] if j not in names]
    return (f"the joint states on {topic} lack the configured joint(s) {missing} (robot.joints); "
            f"they name {names}")


def build_models(config: EstimatorConfig, kinds: Sequence[str] = KINDS, *,
                 n_train: int | None = None, sample_period_s: float | None = None) -> dict[str, Any]:
    """Fresh learners (zero parameters) of the given kinds, sharing one rigid-body regressor.

    Args:
        config: Estimator configuration.
        kinds: Any of ``"P"``, ``"NP"``, ``"SP"`` (the cascade or the joint fit, as the configuration's
            ``semiparametric.combination`` says), :data:`JOINT_SP` (always the joint fit),
            :data:`CASCADE_SP` (always the paper's cascade) and the diagnostic :data:`FROZEN_P` (around the
            cascade).
        n_train: Samples the rigid-body stage of :data:`FROZEN_P` learns (required for it).
        sample_period_s: The stream's sample period [s], measured as the node does
            (:func:`~semiparam_ros.core.stream.rate.measured_period_s` of the first stream learned): it
            converts a warm-up given in seconds, and with ``adaptation.time_constant`` τ > 0 every learner
            forgets with β = exp(−T/τ), as in the node (``None``: the configured factors, warm-up at 100 Hz).

    Returns:
        Models by kind, in the given order.

    Raises:
        ValueError: On an unknown kind, :data:`FROZEN_P` without ``n_train``, or :data:`JOINT_SP` with a
            configuration whose two forgetting factors differ (the joint fit has one data weighting).
    """
    unknown = [k for k in kinds if k not in (*KINDS, *EXTRA_KINDS)]
    if unknown:
        raise ValueError(f"unknown model kind(s) {unknown}; choose from {[*KINDS, *EXTRA_KINDS]}")
    regressor = build_regressor(config) if any(k != "NP" for k in kinds) else None
    models: dict[str, Any] = {}
    for kind in kinds:
        if kind in (FROZEN_P, CASCADE_SP):
            cascade = config.with_overrides({"semiparametric.combination": "cascade"})
            model = build_model(cascade, "SP", regressor, sample_period_s=sample_period_s)
            if kind == CASCADE_SP:
                models[kind] = model
                continue
            if n_train is None:
                raise ValueError(f"{FROZEN_P} needs the number of training samples")
            models[kind] = FrozenParametricSP(model, n_train)
        elif kind == JOINT_SP:
            try:
                joint = config.with_overrides({"semiparametric.combination": "joint"})
            except ValueError as err:
                raise ValueError(f"model kind {JOINT_SP!r} (semiparametric.combination 'joint'): "
                                 f"{err}") from None
            models[kind] = build_model(joint, "SP", regressor, sample_period_s=sample_period_s)
        else:
            models[kind] = build_model(config, kind, regressor, sample_period_s=sample_period_s)
    return models


def evaluate_bags(train_path: str | Path, test_path: str | Path, config: EstimatorConfig, *,
                  topics: Topics | None = None, kinds: Sequence[str] = KINDS,
                  options: ProtocolOptions | None = None,
                  horizons: Sequence[float | str] | None = None, progress: bool = False,
                  jobs: int = 1, cluster: str | None = None,
                  **option_fields: Any) -> tuple[ProtocolResult, dict[str, Any]]:
    """Run the paper's protocol on two bags (and, if asked, the error by the age of the model).

    Args:
        train_path: Training bag (the XY circles).
        test_path: Test bag (the XZ circles).
        config: Estimator configuration the learners and the pipeline are built from.
        topics: Topics to read; default from the configuration.
        kinds: Learners to compare.
        options: Parts, windows and limits (:class:`~semiparam_ros.eval.protocol.options.ProtocolOptions`;
            the test
            limit counts before the skip, so ``train_limit = test_skip = n`` on one bag trains on its first n
            samples and tests on the rest).
        horizons: Ages of the model [s] (0 = one step, ``"frozen"``) for
            :func:`~semiparam_ros.eval.protocol.horizon.evaluate_horizons`, run on the trained learners, the
            CAD model and persistence over the whole test stream; ``None``: not run.
        progress: Show a progress bar (only when stderr is a terminal).
        jobs: Models run in parallel on this machine (1: one after the other; -1: all cores).
        cluster: A Dask scheduler address or ``local:N`` running one job per model instead of ``jobs``;
            the numbers are those of the serial run.
        **option_fields: Fields of :class:`~semiparam_ros.eval.protocol.options.ProtocolOptions` given one by
            one (``splits=…``), replacing those of ``options``.

    Returns:
        ``(result, info)`` where ``info`` records the bags, topics, limits and pipeline drops, and under
        ``"horizons"`` the :class:`~semiparam_ros.eval.protocol.horizon.HorizonReport` when asked.

    Raises:
        ValueError: On unreadable bags or a test bag too short for the split request.
    """
    opts = replace(options or ProtocolOptions(), **option_fields)
    train_limit, test_limit, test_skip = opts.train_limit, opts.test_limit, opts.test_skip
    topics = topics or Topics.from_config(config)
    train_data, train_drops = load_samples(train_path, config, topics, limit=train_limit)
    test_data, test_drops = load_samples(test_path, config, topics, limit=test_limit)
    if isinstance(test_skip, bool) or not isinstance(test_skip, int) or test_skip < 0:
        raise ValueError(f"test_skip must be an integer >= 0, got {test_skip!r}")
    if test_skip:
        if test_skip >= len(test_data):
            raise ValueError(f"test_skip = {test_skip} leaves no test sample (the bag has {len(test_data)})")
        test_data = test_data.slice(test_skip, len(test_data))
    if jobs == 1 and cluster is None:
        result, models_report = _protocol_of(config, tuple(kinds), train_data, test_data, opts, horizons,
                                             progress)
    else:  # one job per model: the same numbers, each model built and trained where it runs
        parts = run_jobs(_protocol_of, [(config, (k,), train_data, test_data, opts, horizons)
                                        for k in kinds], jobs=jobs, cluster=cluster, unit="model",
                         labels=[f"{k} on {Path(test_path).name}" for k in kinds], progress=progress)
        result = ProtocolResult.merge([p[0] for p in parts])
        models_report = None if horizons is None else HorizonReport.merge([p[1] for p in parts])
    info = {
        "train_bag": str(train_path), "test_bag": str(test_path),
        "joint_states_topic": topics.joint_states, "wrench_topic": topics.wrench,
        "ground_truth_topic": topics.ground_truth if test_data.Y_true is not None else None,
        "train_limit": train_limit, "test_limit": test_limit, "test_skip": test_skip,
        "drops_train": train_drops, "drops_test": test_drops,
        "test_samples_available": len(test_data),
    }
    if horizons is not None:
        from semiparam_ros.eval.models.baselines import Persistence, cad_model
        from semiparam_ros.eval.protocol.prequential import train

        persistence = Persistence(test_data.n_outputs)
        train(persistence, train_data)
        components = OutputSpec.from_config(config).components
        cad = evaluate_horizons({"CAD": cad_model(config)}, train_data, test_data, horizons=horizons,
                                fixed=("CAD",), components=components)
        held = evaluate_horizons({"persistence": persistence}, train_data, test_data, horizons=horizons,
                                 components=components)
        assert models_report is not None
        info["horizons"] = HorizonReport.merge([cad, models_report, held])
    return result, info


def _protocol_of(config: EstimatorConfig, kinds: tuple[str, ...], train_data: SampleArrays,
                 test_data: SampleArrays, opts: ProtocolOptions, horizons: Sequence[float | str] | None,
                 progress: bool = False) -> tuple[ProtocolResult, HorizonReport | None]:
    """Run the protocol for fresh learners of ``kinds`` (and their errors by age), as one job.

    P, NP and the SP combinations run as the node runs them
    (:class:`~semiparam_ros.eval.models.served.NodeLearner`:
    the estimator's step with its gate, σ and rate meter); the diagnostic kinds are bare learners.
    """
    from semiparam_ros.eval.models.served import SERVED_COMBINATIONS, node_learner

    bare = [k for k in kinds if k not in SERVED_COMBINATIONS]
    models = build_models(config, bare, n_train=len(train_data),
                          sample_period_s=measured_period_s(train_data.stamps_ns))
    models = {k: models[k] if k in models else node_learner(config, k) for k in kinds}
    result = run_protocol(models, train_data, test_data, output=OutputSpec.from_config(config),
                          splits=opts.splits, split_size=opts.split_size, window_s=opts.window_s,
                          first_s=opts.first_s, progress=progress)
    if horizons is None:
        return result, None
    # the frozen column is the served model: the node learners the protocol trained, their checkpoint,
    # load_model
    from semiparam_ros.eval.models.served import NodeLearner, ServedModel, serve
    from semiparam_ros.eval.protocol.horizon import FROZEN

    served = {}
    if FROZEN in horizons:
        served = {k: ServedModel(serve(m.estimator)) for k, m in models.items() if isinstance(m, NodeLearner)}
    report = evaluate_horizons(models, train_data, test_data, horizons=horizons,
                               components=OutputSpec.from_config(config).components,  # trained above
                               frozen_models=served)
    return result, report


def read_scenario(bag: str | Path, what: str, hint: str = "") -> tuple[Path, Mapping[str, Any] | None]:
    """Read the simulator's ground-truth sidecar ``scenario.yaml`` next to a bag.

    Args:
        bag: Bag folder or ``.mcap`` file (the sidecar is read from the folder).
        what: What the caller wants from it, for the error message (e.g. "the pickup time").
        hint: Appended to the error message (what the user can do instead).

    Returns:
        ``(path, document)``: the sidecar's path and its top-level mapping (None if it is not a mapping).

    Raises:
        ValueError: If the file is missing or is not YAML.
    """
    bag = Path(bag)
    path = (bag if bag.is_dir() else bag.parent) / "scenario.yaml"
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"cannot read {what} from {path}: {err}{hint}") from err
    return path, doc if isinstance(doc, Mapping) else None


def payload_pickup(doc: Mapping[str, Any] | None) -> tuple[float | None, int | None]:
    """Return the payload pickup a sidecar records.

    Args:
        doc: The sidecar's document (:func:`read_scenario`).

    Returns:
        ``(time_s, stamp_ns)``: ``payload.time_s`` [s from the first joint state] and ``payload.stamp_ns``
        [ns], each None when missing or not a number.
    """
    payload = doc.get("payload") if doc is not None else None
    if not isinstance(payload, Mapping):
        return None, None
    time_s, stamp = payload.get("time_s"), payload.get("stamp_ns")
    return (float(time_s) if isinstance(time_s, int | float) and not isinstance(time_s, bool) else None,
            int(stamp) if isinstance(stamp, int) and not isinstance(stamp, bool) else None)


def read_change_time(bag: str | Path) -> tuple[float, int | None]:
    """Read the payload pickup from the simulator's ``scenario.yaml`` next to the bag.

    The simulator records ``payload: {time_s: <s from the bag start>, stamp_ns: <absolute stamp>}``;
    the stamp is exact and preferred by :func:`evaluate_adaptation`.

    Args:
        bag: Bag folder or ``.mcap`` file (``scenario.yaml`` is read from the folder).

    Returns:
        ``(time_s, stamp_ns)``: the pickup time [s from the first joint state] and its stamp [ns] (``None``
        if not recorded).

    Raises:
        ValueError: If the file is missing or records no payload pickup.
    """
    path, doc = read_scenario(bag, "the pickup time", "; pass --pickup-time")
    time_s, stamp_ns = payload_pickup(doc)
    if time_s is None:
        raise ValueError(f"{path} records no payload pickup (payload.time_s); pass --pickup-time")
    return time_s, stamp_ns


def adaptation_configs(config: EstimatorConfig, forgetting: float,
                       forgetting_nonparametric: float | None = None) -> dict[str, EstimatorConfig]:
    """Return the two configurations compared in the payload scenario.

    Args:
        config: Base configuration.
        forgetting: Forgetting factor β of the parametric stage with adaptation on (``0.9 <= β < 1``).
        forgetting_nonparametric: β of the residual stage with adaptation on (default: ``forgetting``;
            may be 1).

    Returns:
        ``{"on": the given β, "off": β = 1 in both stages}``, both with ``adaptation.time_constant`` 0 (the
        comparison is of these factors, whatever the base configuration's memory τ).

    Raises:
        ValueError: If ``forgetting`` is out of range.
    """
    if not 0.9 <= forgetting < 1.0:
        raise ValueError(f"forgetting for the adaptive model must be in [0.9, 1), got {forgetting}")
    beta_np = forgetting if forgetting_nonparametric is None else forgetting_nonparametric
    # adaptation.time_constant off in both: β is what this comparison sets, not the measured-rate default
    return {
        "on": config.with_overrides({"parametric.forgetting": forgetting,
                                     "nonparametric.forgetting": beta_np, "adaptation.time_constant": 0.0}),
        "off": config.with_overrides({"parametric.forgetting": 1.0, "nonparametric.forgetting": 1.0,
                                      "adaptation.time_constant": 0.0}),
    }


def evaluate_adaptation(bag: str | Path, config: EstimatorConfig, *, forgetting: float,
                        forgetting_nonparametric: float | None = None, change_s: float | None = None,
                        pretrain_path: str | Path | None = None,
                        topics: Topics | None = None, kinds: Sequence[str] = ("SP",),
                        window_s: float = DEFAULT_WINDOW_S,
                        pre_s: float = 10.0, deadline_s: float = 10.0, tolerance: float = 1.5,
                        progress: bool = False) -> tuple[AdaptationResult, dict[str, Any]]:
    """Run the payload scenario: each learner with adaptation on (forgetting β) and off (β = 1).

    Args:
        bag: Bag with the payload change.
        config: Base configuration.
        forgetting: β of the parametric stage (and by default of the residual stage) when adaptive.
        forgetting_nonparametric: β of the residual stage when adaptive (default: ``forgetting``).
        change_s: Pickup time [s from the bag's first joint state]; read from ``scenario.yaml`` when
            omitted.
        pretrain_path: Optional bag every learner is trained on first.
        topics: Topics to read.
        kinds: Learners (``"SP"`` by default; ``"P"``, ``"NP"`` and :data:`JOINT_SP` possible).
        window_s: Sliding window [s].
        pre_s: Pre-pickup reference segment [s].
        deadline_s: Recovery deadline after the pickup [s].
        tolerance: Allowed ratio to the pre-pickup level.
        progress: Show a tqdm progress bar.

    Returns:
        ``(result, info)``; models are keyed by :attr:`~semiparam_ros.eval.protocol.options.Variant.label`
        (``"<kind> adaptive (β=...)"``, ``"<kind> no adaptation"``).

    Raises:
        ValueError: On unreadable bags, a missing pickup time or an invalid β.
    """
    topics = topics or Topics.from_config(config)
    change_stamp_ns = None
    if change_s is None:
        change_s, change_stamp_ns = read_change_time(bag)
    stream, drops = load_samples(bag, config, topics)
    # run_adaptation counts from the first sample, which comes after the bag's first joint state (the
    # acceleration estimator's warm-up); the pickup stamp, when recorded, is exact
    if change_stamp_ns is None:
        first_joint_state = next(iter(read_messages(bag, joint_states_topic=topics.joint_states,
                                                    wrench_topic=None))).stamp_ns
        change_stamp_ns = first_joint_state + round(change_s * 1e9)
    change_from_first = (change_stamp_ns - int(stream.stamps_ns[0])) * 1e-9
    pretrain = load_samples(pretrain_path, config, topics)[0] if pretrain_path is not None else None
    configs = adaptation_configs(config, forgetting, forgetting_nonparametric)
    beta_np = forgetting if forgetting_nonparametric is None else forgetting_nonparametric
    models: dict[str, Any] = {}
    period = measured_period_s((pretrain if pretrain is not None else stream).stamps_ns)
    for kind in kinds:
        for key, variant in (("on", Variant(kind, adaptive=True, beta=forgetting, beta_np=beta_np)),
                             ("off", Variant(kind, adaptive=False))):
            models[variant.label] = build_models(configs[key], [kind], sample_period_s=period)[kind]
    result = run_adaptation(models, stream, change_from_first, output=OutputSpec.from_config(config),
                            pretrain=pretrain, window_s=window_s,
                            pre_s=pre_s, deadline_s=deadline_s, tolerance=tolerance, progress=progress)
    info = {"bag": str(bag), "pretrain_bag": None if pretrain_path is None else str(pretrain_path),
            "forgetting": forgetting, "forgetting_nonparametric": beta_np, "pickup_time_s": change_s,
            "pickup_stamp_ns": change_stamp_ns,
            "drops": drops,
            "joint_states_topic": topics.joint_states, "wrench_topic": topics.wrench}
    return result, info
