"""What the semiparametric combinations share: a rigid-body stage and a random-feature stage.

:class:`TwoStageModel` holds a :class:`~semiparam_ros.core.learners.parametric.ParametricModel` and a
:class:`~semiparam_ros.core.learners.nonparametric.NonparametricModel` and implements their common state
(checkpoints, reset, the standardizer warm-up); the cascade (:mod:`~semiparam_ros.core.learners.cascade`),
the joint fit (:mod:`~semiparam_ros.core.learners.joint`) and the consistent model
(:mod:`~semiparam_ros.core.learners.consistent`) derive from it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from semiparam_ros.core.learners.base import LearnerBase, Regressor
from semiparam_ros.core.learners.nonparametric import NonparametricModel
from semiparam_ros.core.learners.parametric import ParametricModel
from semiparam_ros.core.learners.rrls import RecursiveRLS
from semiparam_ros.core.validation import check_finite_array
from semiparam_ros.errors import CheckpointError

__all__ = ["TwoStageModel"]


class TwoStageModel(LearnerBase):
    """Plumbing shared by the two semiparametric models (the cascade and the joint fit).

    Both hold a rigid-body learner ``parametric`` (:class:`ParametricModel`) and a random-feature learner
    ``nonparametric`` (:class:`NonparametricModel`); see :mod:`semiparam_ros.core.learners.joint`.
    """

    parametric: ParametricModel
    nonparametric: NonparametricModel
    n_inputs: int
    n_outputs: int
    n_samples_seen: int

    def rls_stages(self) -> tuple[RecursiveRLS, ...]:
        """Return the two stages' recursive least-squares learners (rigid body first)."""
        return (self.parametric.rls, self.nonparametric.rls)

    @property
    def regressor(self) -> Regressor:
        """The injected regressor callable (shared by copies)."""
        return self.parametric.regressor

    def _check_x(self, x: Any) -> np.ndarray:
        return check_finite_array("x", x, (self.n_inputs,))

    def _check(self, x: Any, y: Any = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        xv = check_finite_array("x", x, (self.n_inputs,))
        yv = None if y is None else check_finite_array("y", y, (self.n_outputs,))
        return xv, yv, self.parametric.phi_cached(xv)

    @property
    def parameters(self) -> np.ndarray:
        """π̂, the rigid-body (base) parameters of the parametric learner (n_params,)."""
        return self.parametric.parameters

    def set_standardizer_warmup(self, warmup: int) -> None:
        """Set the residual stage's online warm-up length [samples] if it is still running.

        Raises:
            ConfigurationError: If ``warmup`` < 1.
        """
        self.nonparametric.set_standardizer_warmup(warmup)

    def learn_held(self) -> None:
        """Learn the residual stage's held warm-up rows once its standardizer is ready (the cascade's)."""
        self.nonparametric.learn_held()

    def reset(self) -> None:
        """Forget both learners (and restart the online standardizer warm-up)."""
        self.parametric.reset()
        self.nonparametric.reset()
        self.n_samples_seen = 0

    def state_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        """Return both learners' state as arrays."""
        state = {f"{prefix}kind": np.array(self._kind),
                 f"{prefix}n_samples_seen": np.array(self.n_samples_seen)}
        state.update(self.parametric.state_dict(f"{prefix}parametric."))
        state.update(self.nonparametric.state_dict(f"{prefix}nonparametric."))
        return state

    def _check_loaded(self, parametric: ParametricModel, nonparametric: NonparametricModel) -> None:
        """Extra consistency checks of a loaded pair of learners (raise CheckpointError); none by default."""

    def load_state_dict(self, state: dict[str, np.ndarray], prefix: str = "") -> None:
        """Replace both learners' state (validated completely before anything changes).

        Raises:
            CheckpointError: Wrong kind, missing keys or sizes that do not match this model.
        """
        self._check_kind(state, prefix)
        p = self.parametric.copy()
        npm = self.nonparametric.copy()
        p.load_state_dict(state, f"{prefix}parametric.")
        npm.load_state_dict(state, f"{prefix}nonparametric.")
        self._check_loaded(p, npm)
        try:
            n_seen = int(state[f"{prefix}n_samples_seen"])
        except KeyError as err:
            raise CheckpointError(f"state is missing key {err}") from err
        self.parametric, self.nonparametric, self.n_samples_seen = p, npm, n_seen
