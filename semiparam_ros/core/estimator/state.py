"""The checkpoint format of :class:`~semiparam_ros.core.estimator.online.OnlineEstimator`.

A checkpoint is one ``.npz`` (:mod:`semiparam_ros.core.checkpoint`): the learners' arrays (``model.*``),
the noise estimate (``noise.*``), the served σ's calibration (``calibration.*``), the contact gate
(``gate.*``), a tared payload (``payload.*``) and the
metadata (``meta.*``: format version, structural fingerprint, samples learned, configuration, URDF, the
robot's identity and the software versions). This module writes and checks the metadata; the estimator
assembles the learned parts.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from semiparam_ros.core.config import EstimatorConfig, structural_values
from semiparam_ros.core.rigid_body.dynamics import RigidBodyRegressor
from semiparam_ros.core.validation import MAX_ABS_INPUT
from semiparam_ros.errors import CheckpointError

#: Format version written to ``meta.version``; an older one is read through
#: :func:`~semiparam_ros.core.estimator.migration.migrate`, a newer one is refused.
CHECKPOINT_VERSION = 4


def software_versions() -> dict[str, str]:
    """Versions of the software a checkpoint is written with (semiparam_ros, Python, NumPy, Pinocchio)."""
    import platform

    import pinocchio

    from semiparam_ros.version import __version__

    return {"semiparam_ros": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "pinocchio": str(pinocchio.__version__)}


def check_magnitudes(path: str | Path, state: dict[str, np.ndarray]) -> None:
    """Refuse a checkpoint whose learned numbers are NaN, inf or beyond ±MAX_ABS_INPUT.

    Raises:
        CheckpointError: Naming the first such array.
    """
    for key, value in state.items():
        arr = np.asarray(value)
        if key.startswith(("model.", "noise.")) and arr.dtype.kind == "f" and arr.size:
            if not np.abs(arr).max() <= MAX_ABS_INPUT:
                raise CheckpointError(f"{path}: corrupt checkpoint: {key} holds NaN, inf or values beyond "
                                      f"{MAX_ABS_INPUT:g}")


# Parameters that fix the shape or meaning of the learned state: a checkpoint is only loaded when these
# match. The learners' hyperparameters are part of it: λ is baked into the factor (RᵀR = λI + ΦᵀΦ), and a
# loaded RecursiveRLS/Standardizer keeps the checkpoint's λ, β and warm-up (even through reset()), so
# accepting a checkpoint written with other values would silently run those while the configuration
# says otherwise. Run-time switches (learning_enabled, checkpoint.*, diagnostics.*) may change.
def fingerprint(config: EstimatorConfig, kind: str, regressor: RigidBodyRegressor) -> str:
    """Return the structure a checkpoint must match to be loaded, as sorted JSON.

    The parameters the parameter table flags as structural
    (:func:`~semiparam_ros.core.config.structural_values`),
    the learner kind and the base parameters' names (friction, offsets and armature show in them).
    """
    structure = structural_values(config, kind)
    structure["kind"] = kind
    structure["base_parameters"] = list(regressor.base_parameter_names)
    return json.dumps(structure, sort_keys=True)


def robot_identity(regressor: RigidBodyRegressor) -> dict[str, Any]:
    """Return the robot a checkpoint is learned on: URDF robot name and CAD base parameters (rounded)."""
    cad = regressor.to_base(regressor.urdf_parameters())
    return {"name": regressor.robot_name, "cad_base_parameters": [float(f"{v:.9g}") for v in cad]}


def meta_arrays(config: EstimatorConfig, kind: str, regressor: RigidBodyRegressor,
                n_samples_learned: int, sample_period_s: float | None = None) -> dict[str, np.ndarray]:
    """Return a checkpoint's ``meta.*`` arrays: what :func:`read_meta` checks; they make it self-contained.

    Args:
        config: The estimator's configuration (``meta.config``, JSON).
        kind: Its learner kind (``P``, ``NP``, ``SP``).
        regressor: Its regressor (``meta.urdf``, ``meta.robot``).
        n_samples_learned: Samples learned so far.
        sample_period_s: The measured sample period [s] the learner converted its constants in seconds at
            (``meta.sample_period_s``, when known: a loaded model takes it until its own stream's period is
            measured, :func:`read_period`).

    Returns:
        Arrays by key: version, fingerprint, samples learned, configuration, URDF, robot, versions, period.
    """
    meta = {
        "meta.version": np.array(CHECKPOINT_VERSION),
        "meta.fingerprint": np.array(fingerprint(config, kind, regressor)),
        "meta.n_samples_learned": np.array(n_samples_learned),
        "meta.config": np.array(json.dumps(config.to_flat(), sort_keys=True)),
        "meta.urdf": np.array(regressor.urdf_xml),
        "meta.robot": np.array(json.dumps(robot_identity(regressor), sort_keys=True)),
        "meta.versions": np.array(json.dumps(software_versions(), sort_keys=True)),
    }
    if sample_period_s is not None:
        meta["meta.sample_period_s"] = np.array(float(sample_period_s))
    return meta


def read_period(state: dict[str, np.ndarray], path: str | Path) -> float | None:
    """Return the sample period [s] a checkpoint was learned at (``meta.sample_period_s``), or None.

    Args:
        state: Checkpoint arrays.
        path: Where they came from, for messages.

    Raises:
        CheckpointError: A stored period that is not one finite number > 0.
    """
    if "meta.sample_period_s" not in state:
        return None
    try:
        period = float(np.asarray(state["meta.sample_period_s"], dtype=np.float64).item())
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: corrupt checkpoint: meta.sample_period_s: {err}") from err
    if not (math.isfinite(period) and period > 0.0):
        raise CheckpointError(f"{path}: corrupt checkpoint: meta.sample_period_s = {period!r} is not a "
                              "period > 0 s")
    return period


def read_meta(state: dict[str, np.ndarray], path: str | Path, config: EstimatorConfig, kind: str,
              regressor: RigidBodyRegressor) -> int:
    """Check a checkpoint's metadata against the estimator that loads it.

    Args:
        state: Checkpoint arrays.
        path: Where they came from, for messages.
        config: The loading estimator's configuration.
        kind: Its learner kind.
        regressor: Its regressor.

    Returns:
        The number of samples the checkpoint learned.

    Raises:
        CheckpointError: Not a checkpoint, corrupt metadata, another version, another model structure or
            another robot (URDF name or CAD inertial parameters).
    """
    try:
        version = _scalar(state["meta.version"], int)
        saved = _scalar(state["meta.fingerprint"], str)
        n_learned = _scalar(state["meta.n_samples_learned"], int)
    except KeyError as err:
        raise CheckpointError(f"{path}: not a semiparam_ros checkpoint (missing {err})") from err
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: corrupt checkpoint metadata: {err}") from err
    if version != CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: checkpoint version {version}, expected {CHECKPOINT_VERSION}")
    current = fingerprint(config, kind, regressor)
    if saved != current:
        raise CheckpointError(f"{path}: checkpoint was written for another model structure: "
                              f"{_fingerprint_difference(saved, current)}")
    if n_learned < 0:
        raise CheckpointError(f"{path}: corrupt checkpoint: {n_learned} samples learned")
    if "meta.robot" not in state:
        raise CheckpointError(f"{path}: corrupt checkpoint: it names no robot (meta.robot)")
    _check_robot(path, state["meta.robot"], regressor)
    return n_learned


def read_version(state: dict[str, np.ndarray], path: str | Path = "checkpoint") -> int:
    """Return a checkpoint's format version (``meta.version``).

    Raises:
        CheckpointError: Not a checkpoint, or a version that is not one integer.
    """
    try:
        return _scalar(state["meta.version"], int)
    except KeyError as err:
        raise CheckpointError(f"{path}: not a semiparam_ros checkpoint (missing {err})") from err
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: corrupt checkpoint metadata: {err}") from err


def _check_robot(path: str | Path, saved: np.ndarray, regressor: RigidBodyRegressor) -> None:
    """Refuse a checkpoint learned on another robot (other URDF name or CAD inertial parameters)."""
    try:
        identity = json.loads(_scalar(saved, str))
        name, cad = identity["name"], np.asarray(identity["cad_base_parameters"], dtype=np.float64)
    except (TypeError, ValueError, KeyError) as err:
        raise CheckpointError(f"{path}: corrupt checkpoint metadata meta.robot: {err}") from err
    mine = robot_identity(regressor)
    ours = np.asarray(mine["cad_base_parameters"])
    if name != mine["name"]:
        raise CheckpointError(f"{path}: checkpoint was learned on robot {name!r}, this configuration's "
                              f"URDF describes {mine['name']!r}")
    if cad.shape != ours.shape or not np.allclose(cad, ours, rtol=1e-6, atol=1e-9):
        raise CheckpointError(f"{path}: checkpoint was learned on a URDF of {name!r} with other inertial "
                              "parameters (its CAD prior differs from this configuration's URDF); use "
                              "the URDF it was learned with, or start afresh")


def read_config(path: str | os.PathLike[str],
                state: dict[str, np.ndarray]) -> tuple[EstimatorConfig, str, dict[str, Any]]:
    """Return the configuration, URDF text and software versions a self-contained checkpoint carries.

    Args:
        path: Where the arrays came from, for messages.
        state: Checkpoint arrays.

    Returns:
        ``(config, urdf_xml, versions)``.

    Raises:
        CheckpointError: Not a checkpoint, a checkpoint written before checkpoints carried their
            configuration, or corrupt metadata.
    """
    if "meta.fingerprint" not in state:
        raise CheckpointError(f"{path}: not a semiparam_ros checkpoint (no meta.fingerprint)")
    if "meta.config" not in state or "meta.urdf" not in state:
        raise CheckpointError(f"{path}: this checkpoint does not carry its configuration and URDF (written "
                              "by an older version): load it with OnlineEstimator(load_config(C)).load(path)"
                              " and save it again to make it self-contained")
    try:
        flat = json.loads(str(np.asarray(state["meta.config"])))
        urdf = str(np.asarray(state["meta.urdf"]))
        versions = json.loads(str(np.asarray(state.get("meta.versions", np.array("{}")))))
        if not isinstance(flat, dict) or not isinstance(versions, dict):
            raise TypeError("not a JSON object")
        config = EstimatorConfig.from_flat(flat)
    except (TypeError, ValueError) as err:  # ConfigurationError is a ValueError
        raise CheckpointError(f"{path}: corrupt checkpoint metadata (configuration): {err}") from err
    return config, urdf, versions


def learner_kind(state: dict[str, np.ndarray]) -> Any:
    """Return the learner kind (``P``, ``NP``, ``SP``) a checkpoint's fingerprint names.

    Raises:
        CheckpointError: On a corrupt fingerprint or an unknown kind.
    """
    try:
        kind = json.loads(str(np.asarray(state["meta.fingerprint"]))).get("kind", "SP")
    except (ValueError, AttributeError) as err:
        raise CheckpointError(f"corrupt checkpoint fingerprint: {err}") from err
    if kind not in ("P", "NP", "SP"):
        raise CheckpointError(f"checkpoint holds an unknown learner kind {kind!r}")
    return kind


def _scalar(value: np.ndarray, kind: type[int] | type[str]) -> Any:
    """Read a 0-d array of a checkpoint as an int or a str.

    Raises:
        ValueError: If the array is not 0-d or not of that kind.
    """
    arr = np.asarray(value)
    if arr.ndim != 0:
        raise ValueError(f"expected a scalar, got an array of shape {arr.shape}")
    if kind is int:
        if arr.dtype.kind not in "iu":
            raise ValueError(f"expected an integer, got dtype {arr.dtype}")
        return int(arr)
    if arr.dtype.kind != "U":
        raise ValueError(f"expected a string, got dtype {arr.dtype}")
    return str(arr)


def _fingerprint_difference(saved: str, current: str) -> str:
    """Name the entries that differ between two fingerprints (for the error message)."""
    try:
        a, b = json.loads(saved), json.loads(current)
    except ValueError:
        return f"unreadable fingerprint {saved!r}"
    if not isinstance(a, dict):
        return f"unreadable fingerprint {saved!r}"
    names = sorted(set(a) | set(b))
    text = "; ".join(f"{k} = {a.get(k)!r} in the checkpoint, {b.get(k)!r} now" for k in names
                     if a.get(k) != b.get(k))
    key = "semiparametric.combination"
    if "kind" in a and a.get(key) is None and b.get(key) not in (None, "cascade"):
        # a fingerprint without the key was written by the paper's cascade, the default until the
        # consistent learner became it
        text += (f" (a checkpoint without {key} holds the paper's cascade: set {key}: cascade to load "
                 "it, or start the new default learner afresh)")
    return text
