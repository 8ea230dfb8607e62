"""Gymnasium wrappers that put an estimator between the sensors and the agent.

The agent sees the estimate instead of the raw sensor output. Each step, the wrapper feeds the
estimator the input actually applied (``info["action_applied"]``, physical units) and the new
sensor output with its validity mask, and adds to ``info``:

* ``estimate`` ``(n,)``: the estimate (also the observation, as float32);
* ``covariance`` ``(n, n)``: its covariance (NaN for observers without one);
* ``innovation`` ``(m,)``: measurement minus prediction;
* ``estimator_diverged``: the estimator's divergence flag.

``EstimatorWrapper`` wraps a single environment, ``VectorEstimatorWrapper`` a (native or
Gymnasium) vector environment with next-step autoreset; :func:`wrap` picks the right one.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space
from numpy.typing import ArrayLike, NDArray

from .base import Estimator


def _estimate_space(estimator: Estimator) -> spaces.Box:
    n = len(estimator.state_names)
    big = np.finfo(np.float32).max  # estimates are unbounded; inf bounds upset checkers
    return spaces.Box(-big, big, (n,), dtype=np.float32)


def _check_channels(env: Any, estimator: Estimator) -> None:
    system = getattr(env.unwrapped, "system", None)
    if system is not None and system.channels != tuple(estimator.measurement_names):
        raise ValueError(f"the estimator expects measurements {estimator.measurement_names}; "
                         f"the environment's sensors give {system.channels}")


class EstimatorWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """One environment whose observation is an estimator's estimate.

    :param env: a marine environment (or any env whose ``info`` has ``action_applied`` and
        whose observation is the sensor output the estimator expects).
    :param estimator: bound to a batch of one by the wrapper.
    :param x0, P0: initial estimate and covariance at each reset (default: the estimator's).
    :param reinitialise_on_divergence: restart the estimator from ``x0, P0`` and the current
        measurement when it diverges (``info["estimator_diverged"]`` still reports it).
    """

    def __init__(self, env: gym.Env, estimator: Estimator, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, reinitialise_on_divergence: bool = False) -> None:
        # recorded so that env.spec can rebuild the stack (Gymnasium's checker does)
        gym.utils.RecordConstructorArgs.__init__(
            self, estimator=estimator, x0=x0, P0=P0,
            reinitialise_on_divergence=reinitialise_on_divergence)
        gym.Wrapper.__init__(self, env)
        _check_channels(env, estimator)
        self.estimator, self.x0, self.P0 = estimator, x0, P0
        self.reinitialise_on_divergence = reinitialise_on_divergence
        self.observation_space = _estimate_space(estimator)
        estimator.bind(1)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.estimator.reset(self.x0, self.P0)
        return self._correct(obs, info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.estimator.predict(np.asarray(info["action_applied"])[None])
        estimate, info = self._correct(obs, info)
        return estimate, reward, terminated, truncated, info

    def _correct(self, obs: np.ndarray, info: dict[str, Any]):
        est = self.estimator
        mask = info.get("measurement_mask")
        est.update(np.asarray(obs, dtype=float)[None], None if mask is None else mask[None])
        diverged = bool(est.diverged[0])
        if diverged and self.reinitialise_on_divergence:
            est.reset(self.x0, self.P0)
            est.update(np.asarray(obs, dtype=float)[None], None if mask is None else mask[None])
        info = {**info, "estimate": est.x[0].copy(), "covariance": np.array(est.P[0]),
                "innovation": est.innovation[0].copy(), "estimator_diverged": diverged}
        return est.x[0].astype(np.float32), info


class VectorEstimatorWrapper(VectorWrapper):
    """A vector environment whose observations are a batch of estimates (one filter per
    sub-environment; a sub-environment's filter restarts when it autoresets).

    Parameters as :class:`EstimatorWrapper`.
    """

    def __init__(self, env: VectorEnv, estimator: Estimator, x0: ArrayLike | None = None,
                 P0: ArrayLike | None = None, reinitialise_on_divergence: bool = False) -> None:
        super().__init__(env)
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if mode != AutoresetMode.NEXT_STEP:
            raise ValueError(f"autoreset_mode {mode!r} is not supported: use NEXT_STEP")
        _check_channels(env, estimator)
        self.estimator, self.x0, self.P0 = estimator, x0, P0
        self.reinitialise_on_divergence = reinitialise_on_divergence
        self.single_observation_space = _estimate_space(estimator)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)
        estimator.bind(env.num_envs)
        self._restarting = np.zeros(env.num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self.estimator.reset(self.x0, self.P0)
        self._restarting[:] = False
        return self._correct(obs, info)

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        est = self.estimator
        est.predict(np.asarray(info["action_applied"], dtype=float))
        # sub-environments that finished last step were reset by this one: new filters
        if self._restarting.any():
            est.reset(self.x0, self.P0, idx=np.flatnonzero(self._restarting))
        self._restarting = np.asarray(terminated) | np.asarray(truncated)
        estimate, info = self._correct(obs, info)
        return estimate, reward, terminated, truncated, info

    def restart(self, idx: NDArray[np.intp]) -> tuple[np.ndarray, np.ndarray]:
        """The environment's :meth:`~marine_envs.envs.base.MarineVectorEnv.restart` of boats
        ``idx``, their filters restarted on its first measurements: their estimates
        ``(len(idx), n)`` and the valid channels."""
        idx = np.asarray(idx, dtype=np.intp)
        y_idx, valid_idx = self.env.restart(idx)
        est = self.estimator
        est.reset(self.x0, self.P0, idx=idx)
        y = np.zeros((self.num_envs, y_idx.shape[1]))
        mask = np.zeros(y.shape, dtype=bool)  # the other filters see no data
        y[idx], mask[idx] = y_idx, valid_idx
        est.update(y, mask)
        self._restarting[idx] = False  # restarted already, not again on the next step
        return est.x[idx].astype(np.float32), valid_idx

    def _correct(self, obs: np.ndarray, info: dict[str, Any]):
        est = self.estimator
        y = np.asarray(obs, dtype=float)
        mask = info.get("measurement_mask")
        est.update(y, mask)
        diverged = est.diverged.copy()
        if diverged.any() and self.reinitialise_on_divergence:
            est.reset(self.x0, self.P0, idx=np.flatnonzero(diverged))
            # only the restarted filters take the measurement again
            again = diverged[:, None] & (True if mask is None else np.asarray(mask, dtype=bool))
            est.update(y, np.broadcast_to(again, y.shape))
        everyone = np.ones(self.num_envs, dtype=bool)
        info = {**info, "estimate": est.x.copy(), "_estimate": everyone,
                "covariance": np.array(est.P), "_covariance": everyone,
                "innovation": est.innovation.copy(), "_innovation": everyone,
                "estimator_diverged": diverged, "_estimator_diverged": everyone}
        return est.x.astype(np.float32), info


def wrap(env: gym.Env | VectorEnv, estimator: Estimator, **kwargs: Any):
    """:class:`VectorEstimatorWrapper` for a vector environment, else :class:`EstimatorWrapper`."""
    cls = VectorEstimatorWrapper if isinstance(env, VectorEnv) else EstimatorWrapper
    return cls(env, estimator, **kwargs)


class TrueStateWrapper(VectorWrapper):
    """A marine vector environment whose observation is the true state (``info["state"]``):
    the oracle a perfect estimator would give, the lower bound of an estimator comparison.

    Same interface as :class:`VectorEstimatorWrapper` (``restart`` included), so controllers
    and SB3 agents take it wherever they take an estimate.
    """

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        model = env.unwrapped.system.model
        self.state_names = tuple(model.state_names)
        big = np.finfo(np.float32).max
        self.single_observation_space = spaces.Box(-big, big, (len(self.state_names),),
                                                   dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)

    def _state(self) -> NDArray[np.float32]:
        return self.env.unwrapped.true_state.astype(np.float32)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        _, info = self.env.reset(seed=seed, options=options)
        return self._state(), info

    def step(self, actions):
        _, reward, terminated, truncated, info = self.env.step(actions)
        return self._state(), reward, terminated, truncated, info

    def restart(self, idx: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Start new episodes of boats ``idx`` now; returns their true states and an all-valid
        mask (see ``MarineVectorEnv.restart``)."""
        idx = np.asarray(idx, dtype=np.intp)
        self.env.restart(idx)
        return self._state()[idx], np.ones((idx.size, len(self.state_names)), dtype=bool)
