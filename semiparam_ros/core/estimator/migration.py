"""The one migration path of the checkpoint format: an older checkpoint's arrays brought to today's layout.

Each format version adds or changes arrays; :func:`migrate` converts a checkpoint of any earlier version
step by step to :data:`~semiparam_ros.core.estimator.state.CHECKPOINT_VERSION`, so that the learners and
the estimator read one layout only (a missing array in a current checkpoint is a corrupt file, not an old
one). What a step fills in is what the model of that version did without the array, so a migrated
checkpoint predicts and learns as it did when it was written. Each step says what it did, once, in the
notes it returns (the node logs them at a warm start).

Version 1 (before the format was versioned by migration) → 2, by the arrays the model keeps:

* ``noise.*``, ``gate.*`` absent (written before checkpoints carried σ and the contact gate): a fresh
  noise estimate and gate, as a new model has.
* ``meta.robot`` absent (written before checkpoints named their robot): the robot of the configuration
  that loads it (nothing to check it against).
* a rigid-body learner's ``prior`` absent (written before priors existed): zero.
* a residual's ``held_x``/``held_y`` absent (written before the warm-up rows were held): none.
* a standardizer's ``min_scale`` absent: 0 (no floor).
* the consistent SP's ``scales`` without the correlation statistics: none (c = 1); its ``reference``
  without the flag of a rigid body set from outside: a reference that followed π̂; its residual in the
  layout that regressed every learned regressor entry: today's layout (the reference's residual and the
  cross-products ``B_E = Rᵀ d_E``, exact).

Version 2 → 3: ``calibration.*`` (the served σ's scales for new motion,
:mod:`semiparam_ros.core.estimator.calibration`) absent: empty histograms, i.e. the served σ is the one-step
σ, as before; ``stick.*`` (friction that remembers, :mod:`semiparam_ros.core.learners.stick`) absent:
c = 0, no torque held, as before.

Version 3 → 4: the consistent SP's ``aged`` and ``aged_copies`` (the test of its residual on an aged copy,
:meth:`~semiparam_ros.core.learners.consistent.ConsistentSemiparametricModel.residual_use`) absent: no
evidence yet, i.e. the residual used on every output, as before.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from semiparam_ros.errors import CheckpointError

__all__ = ["migrate"]

#: A step from one version to the next: ``(state, fresh) -> (state, notes)``.
Step = Callable[[dict[str, np.ndarray], Callable[[], dict[str, np.ndarray]]],
                tuple[dict[str, np.ndarray], list[str]]]


def migrate(state: dict[str, np.ndarray], version: int, target: int,
            fresh: Callable[[], dict[str, np.ndarray]], path: str | Path = "checkpoint",
            ) -> tuple[dict[str, np.ndarray], list[str]]:
    """Bring the arrays of a checkpoint of ``version`` to the layout of ``target``.

    Args:
        state: The checkpoint's arrays (not modified).
        version: Its ``meta.version``.
        target: The version to reach (the current one).
        fresh: Returns the checkpoint arrays of a new model of the same configuration (called at most
            once, and only for a checkpoint older than ``target``).
        path: Where the arrays came from, for messages.

    Returns:
        ``(state, notes)``: the migrated arrays (``meta.version`` = ``target``) and one line per step.

    Raises:
        CheckpointError: A version newer than ``target`` or unknown, or arrays a step cannot convert.

    >>> new, notes = migrate({"meta.version": np.array(3)}, 3, 3, dict)
    >>> notes
    []
    """
    if version == target:
        return state, []
    if version > target or version not in _STEPS:
        raise CheckpointError(f"{path}: checkpoint version {version}, this version reads 1 to {target} "
                              "(a checkpoint of a newer semiparam_ros: update it)")
    cache: list[dict[str, np.ndarray]] = []

    def fresh_once() -> dict[str, np.ndarray]:
        if not cache:
            cache.append(fresh())
        return cache[0]

    notes: list[str] = []
    state = dict(state)
    try:
        while version < target:
            state, said = _STEPS[version](state, fresh_once)
            notes += [f"{path}: {line}" for line in said]
            version += 1
    except (KeyError, ValueError, IndexError, TypeError) as err:
        raise CheckpointError(f"{path}: corrupt checkpoint of version {version}: {type(err).__name__}: "
                              f"{err}") from err
    state["meta.version"] = np.array(target)
    return state, notes


def _v1_to_v2(state: dict[str, np.ndarray], fresh: Callable[[], dict[str, np.ndarray]]
              ) -> tuple[dict[str, np.ndarray], list[str]]:
    notes = ["checkpoint of format version 1, read as version 2"]
    new = fresh()
    for group, what in (("noise.", "σ's noise estimate"), ("gate.", "the contact gate")):
        if not any(k.startswith(group) for k in state):
            state.update({k: v for k, v in new.items() if k.startswith(group)})
            notes.append(f"it carries no {what}: starts afresh")
    if "meta.robot" not in state:
        state["meta.robot"] = new["meta.robot"]
        notes.append("it names no robot: taken as the configuration's")
    for key, value in new.items():
        if key in state or not key.startswith("model."):
            continue
        if key.endswith(".prior") or key == "model.prior":
            state[key] = np.zeros_like(value)  # the rigid body of then had a zero prior
        elif key.endswith(("held_x", "held_y")):
            state[key] = np.zeros((0, *np.shape(value)[1:]))
        elif key.endswith("min_scale"):
            state[key] = np.zeros_like(np.asarray(value, dtype=np.float64))
    if "model.phi_entries" in new:
        _consistent_v1(state, new, "model.")
    return state, notes


def _consistent_v1(state: dict[str, np.ndarray], new: dict[str, np.ndarray], prefix: str) -> None:
    """Convert the consistent SP's arrays of version 1: correlation statistics, reference, residual layout."""
    t = int(np.asarray(new[f"{prefix}parametric.n_outputs"]))
    scales = state.get(f"{prefix}scales")
    if scales is not None and np.shape(scales) == (3 + 4 * t,):
        state[f"{prefix}scales"] = np.concatenate([np.asarray(scales, dtype=np.float64), np.zeros(2 * t)])
    key = f"{prefix}nonparametric.rls."
    E = np.asarray(new[f"{prefix}phi_entries"]).size
    converted = False
    if f"{prefix}entries_rhs" not in state and int(np.asarray(state[f"{key}n_outputs"])) == t + E:
        M = np.asarray(state[f"{key}M"], dtype=np.float64)
        D = M.shape[0]
        if M.shape != (D, D + t + E) or not np.isfinite(M).all():
            raise ValueError("the residual learner's state has the wrong size or invalid values")
        R = np.triu(M[:, :D])
        state[f"{key}M"] = np.ascontiguousarray(M[:, :D + t])
        state[f"{key}n_outputs"] = np.array(t)
        state[f"{prefix}entries_rhs"] = R.T @ M[:, D + t:]
        prior = np.asarray(state[f"{prefix}parametric.prior"], dtype=np.float64)
        state[f"{prefix}reference"] = np.concatenate([prior.reshape(-1), [0.0, 0.0]])
        converted = True
    reference = state.get(f"{prefix}reference")
    p = np.asarray(new[f"{prefix}parametric.prior"]).size
    if reference is not None and np.shape(reference) == (p + 1,):
        # without the flag: a reference that followed π̂; re-referenced to the learned π̂ when loaded
        state[f"{prefix}reference"] = np.concatenate([np.asarray(reference, dtype=np.float64), [0.0]])
    if converted:
        ref = np.asarray(state[f"{prefix}reference"], dtype=np.float64)
        ref[p + 1] = 1.0  # "it predicted with the learned parameters": re-referenced when loaded
        state[f"{prefix}reference"] = ref


def _v2_to_v3(state: dict[str, np.ndarray], fresh: Callable[[], dict[str, np.ndarray]]
              ) -> tuple[dict[str, np.ndarray], list[str]]:
    new = fresh()
    notes = []
    for group, note in (("calibration.", "it carries no calibration of σ for new motion: the served σ is the "
                                         "one-step σ until the model has learned another block"),
                        ("stick.", "it carries no friction that remembers: none until the model learns")):
        added = {k: v for k, v in new.items() if k.startswith(group)}
        if added:  # (none when the loading configuration has no such part)
            state.update(added)
            notes.append(note)
    return state, notes


def _v3_to_v4(state: dict[str, np.ndarray], fresh: Callable[[], dict[str, np.ndarray]]
              ) -> tuple[dict[str, np.ndarray], list[str]]:
    new = fresh()
    added = {k: v for k, v in new.items() if k.endswith((".aged", ".aged_copies")) and k not in state}
    state.update(added)
    notes = (["it carries no test of the residual on an aged copy: the residual is used on every output "
              "until the model has learned a few tenths of a second more"] if added else [])
    return state, notes


_STEPS: dict[int, Step] = {1: _v1_to_v2, 2: _v2_to_v3, 3: _v3_to_v4}
