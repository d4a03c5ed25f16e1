"""The node's learning loop without ROS: a bounded input queue, the overload policy, the learned version.

The node (:mod:`semiparam_ros.ros.estimator_node`) converts each message, hands it to
:meth:`LearningLoop.enqueue` and publishes what :meth:`LearningLoop.step` returns; this module never
imports rclpy, so the policy is tested without a middleware. One thread steps the loop; other threads (the
checkpoint writer, services) read the estimator only under :attr:`LearningLoop.lock`.

Overload policy (``overload.max_delay``, s): a sample that waited longer than the budget — or would wait
behind the previous sample's deferred update beyond it — is predicted at once with the residual held
from the last full prediction and not learned (``learning_skipped``); the deferred update of a learned
sample runs in an idle turn (:meth:`LearningLoop.apply_pending`). The longest piece of work a prediction
waits for is then one triangular solve or one update, never both.

>>> from semiparam_ros.core.config import ICUB_RIGHT_ARM, EstimatorConfig
>>> est = OnlineEstimator(EstimatorConfig.from_flat(ICUB_RIGHT_ARM))
>>> loop = LearningLoop(est, queue_size=2, max_delay_s=0.0)
>>> [loop.enqueue(InputKind.WRENCH, None, t) for t in (0.0, 1.0, 2.0)]  # the third one drops the oldest
[False, False, True]
>>> [t for _, _, t in loop.queue]
[1.0, 2.0]
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from semiparam_ros.core.config import EstimatorConfig
from semiparam_ros.core.estimator.online import OnlineEstimator, StepResult
from semiparam_ros.core.kinds import InputKind, OutputKind
from semiparam_ros.core.stream.messages import InputMessage, JointStateData, WrenchData

__all__ = ["Input", "LearningLoop", "Stepped", "warm_up_kernels"]

#: A converted input message.
Input = InputMessage
#: What :meth:`LearningLoop.drain` hands on after each step: the input, what it produced, its arrival time.
OnStep = Callable[[Input, "Stepped", float], None]

_FUSED_COST_RATE = 0.05  # exponential-mean weight of the measured cost of a fused step (≈ 20 steps)


class Stepped(NamedTuple):
    """What one input produced.

    Attributes:
        results: One result per sample the input completed (a priori predictions; learned or not).
        new_drops: Inputs the pipeline or the learner refused since the previous step (counted drops).
    """

    results: list[StepResult]
    new_drops: int


class LearningLoop:
    """A bounded queue of converted inputs in front of an :class:`OnlineEstimator`.

    Args:
        estimator: The estimator the loop drives (the loop owns it: read it only under :attr:`lock`).
        queue_size: Inputs held at most; a full queue drops its oldest input (:meth:`enqueue`).
        max_delay_s: ``overload.max_delay`` [s]; 0 learns every sample whatever its wait.

    Attributes:
        lock: Held by every call that touches the estimator; other threads copy state under it.
        queue: The waiting inputs, ``(kind, data, t_recv)`` with ``t_recv`` a ``time.perf_counter()`` [s].
        max_delay_s: ``overload.max_delay`` [s] (a run-time parameter: :meth:`apply_runtime_parameters`).
        version: Bumped whenever the learned state changes (a learned sample, a reset).
    """

    def __init__(self, estimator: OnlineEstimator, *, queue_size: int, max_delay_s: float) -> None:
        self.estimator = estimator
        self.lock = threading.Lock()
        self.queue: collections.deque[tuple[InputKind, Any, float]] = collections.deque()
        self.queue_size = int(queue_size)
        self.max_delay_s = float(max_delay_s)
        self.version = 0
        self._fused_cost_s = 0.0  # measured cost of a step that also applies a deferred update [s]
        self._drop_total = 0

    def enqueue(self, kind: InputKind, item: Input, t_recv: float | None = None) -> bool:
        """Queue an input received at ``t_recv`` (now when None); returns whether the oldest was dropped."""
        dropped = len(self.queue) >= self.queue_size
        if dropped:
            self.queue.popleft()
        self.queue.append((kind, item, time.perf_counter() if t_recv is None else t_recv))
        return dropped

    def late(self, t_recv: float) -> bool:
        """Return whether the input received at ``t_recv`` is predicted at once and not learned (overload).

        Late: it waited longer than ``max_delay_s``, or the learner still holds the previous sample's
        deferred update and a step that applies it as well (its cost measured over the recent such steps)
        would end beyond the budget.
        """
        budget = self.max_delay_s
        if budget <= 0.0:
            return False
        age = time.perf_counter() - t_recv
        return age > budget or (self.estimator.has_pending and age + self._fused_cost_s > budget)

    def step(self, data: Input, *, skip_learning: bool = False) -> Stepped:
        """Predict, then learn (unless ``skip_learning``) the samples one input completes.

        Raises:
            Exception: Only a programming error: bad input is dropped and counted by the estimator.
        """
        est = self.estimator
        with self.lock:
            fused = not skip_learning and est.has_pending  # this step applies the previous update too
            results = est.process(data, skip_learning=skip_learning)
            for r in results:
                if r.learned:
                    self.version += 1
                    break
            drop_total = est.n_dropped  # refused samples too
        if fused:
            for r in results:
                if r.learned:
                    self._fused_cost_s += _FUSED_COST_RATE * (r.latency_s - self._fused_cost_s)
        new_drops, self._drop_total = drop_total - self._drop_total, drop_total
        return Stepped(results, new_drops)

    def drain(self, max_inputs: int, *, before_each: Callable[[], None] | None = None,
              on_step: OnStep | None = None, deadline: float | None = None, learn_late: bool = False) -> int:
        """Step the queued inputs in arrival order: at most ``max_inputs``, and until ``deadline``.

        The one place inputs leave the queue. Each input is learned unless it is :meth:`late` (overload
        policy); the node publishes what ``on_step`` receives, shutdown learns the rest without publishing.

        Args:
            max_inputs: Inputs stepped at most (a batch, so that the caller's other work gets turns).
            before_each: Called before each input (the node answers a waiting controller first).
            on_step: Called after each input with ``(input, stepped, t_recv)``.
            deadline: A ``time.monotonic()`` [s] after which no further input is started.
            learn_late: Learn every input however late (shutdown), instead of the overload policy.

        Returns:
            The number of inputs stepped.

        Raises:
            Exception: Only a programming error (see :meth:`step`).
        """
        n = 0
        while self.queue and n < max_inputs and (deadline is None or time.monotonic() < deadline):
            if before_each is not None:
                before_each()
            _, data, t_recv = self.queue.popleft()
            stepped = self.step(data, skip_learning=not learn_late and self.late(t_recv))
            if on_step is not None:
                on_step(data, stepped, t_recv)
            n += 1
        return n

    def apply_runtime_parameters(self, config: EstimatorConfig, targets: set[str]) -> None:
        """Take the run-time parameters of ``targets`` (``estimator``, ``loop``) from ``config``."""
        if "loop" in targets:
            self.max_delay_s = float(config["overload.max_delay"])
        if "estimator" in targets:
            with self.lock:
                self.estimator.apply_runtime_parameters(config)

    def apply_pending(self) -> bool:
        """Apply the learners' deferred update if no input waits; returns whether it ran."""
        if self.queue:
            return False
        with self.lock:
            self.estimator.apply_pending()
        return True

    def reset(self) -> None:
        """Forget everything learned (and the drop counts: the next step reports none of the old ones)."""
        with self.lock:
            self.estimator.reset()
            self.version += 1
            self._drop_total = 0

    def learn_remaining(self, budget_s: float) -> int:
        """Learn the queued inputs without publishing, within ``budget_s`` [s]; returns how many ran."""
        return self.drain(len(self.queue), deadline=time.monotonic() + budget_s, learn_late=True)

    def snapshot(self) -> tuple[dict[str, np.ndarray], int, int]:
        """Copy the checkpoint state under the lock: ``(state, version, samples learned)``."""
        with self.lock:
            est = self.estimator
            return est.checkpoint_state(), self.version, est.n_samples_learned


def warm_up_kernels(config: EstimatorConfig, estimator: OnlineEstimator, *, max_samples: int = 2000) -> int:
    """Run every compiled kernel of a step once, on a throw-away estimator sharing ``estimator``'s regressor.

    The same configuration with 4 random features, fed synthetic samples (a slow ramp of every joint,
    zero wrench, 1 ms apart) until three went through the whole step: compilation depends only on the
    array types, so this loads the machine code the real model runs (without it the first real sample
    took ≈ 20–40 ms instead of ≈ 0.3 ms) without copying a model that can hold hundreds of MB.

    Args:
        config: The estimator's configuration.
        estimator: The real estimator (its regressor is stateless between calls: the URDF is not parsed
            a second time).
        max_samples: Synthetic joint states fed at most (the acceleration estimator's warm-up decides).

    Returns:
        The number of synthetic samples that went through the step (≥ 3 unless the cap was reached).
    """
    scratch = OnlineEstimator(config.with_overrides({"nonparametric.n_features": 4,
                                                     "nonparametric.standardizer_warmup": 2}),
                              regressor=estimator.regressor)
    joints = tuple(config["robot.joints"])
    n = len(joints)
    wrench = config.output_kind == OutputKind.WRENCH
    frame_id = config["robot.frame_id"] or "warm_up"  # the frame the pipeline expects, or any
    stepped = 0
    for k in range(max_samples):
        stamp = 1_000_000_000 + k * 1_000_000
        stepped += len(scratch.process(
            JointStateData(stamp, joints, np.full(n, 1e-3 * k), np.full(n, 1.0), np.zeros(n))))
        if wrench:
            stepped += len(scratch.process(
                WrenchData(stamp, frame_id, np.zeros(3), np.zeros(3))))
        if stepped >= 3:
            break
    return stepped
