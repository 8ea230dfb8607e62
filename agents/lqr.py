"""LQR from a model's linearisation, acting on whatever the environment observes.

The gain minimises the environment's own stage cost ``x'Qx + u'Ru`` (same Q, R), so LQR and RL
agents are compared on one number. The policy has Stable-Baselines3's ``predict`` signature, so
one evaluation loop runs both.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray


def lqr_gain(A: ArrayLike, B: ArrayLike, Q: ArrayLike, R: ArrayLike,
             dt: float | None = None) -> NDArray[np.float64]:
    """State-feedback gain K of ``u = -K x``.

    :param A, B: continuous-time model ``x_dot = A x + B u``.
    :param Q, R: state and input weights (Q >= 0, R > 0).
    :param dt: if given, the discrete LQR of the zero-order-hold discretisation with period
        ``dt`` (s), minimising ``sum_k x_k'Q x_k + u_k'R u_k``; else the continuous LQR.
    :raises ValueError: shapes that do not match, or R not positive definite.
    """
    A, B, Q, R = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, Q, R))
    n, m = B.shape
    if A.shape != (n, n) or Q.shape != (n, n) or R.shape != (m, m):
        raise ValueError(f"shapes do not match: A {A.shape}, B {B.shape}, Q {Q.shape}, "
                         f"R {R.shape}")
    if np.linalg.eigvalsh((R + R.T) / 2).min() <= 0:
        raise ValueError("R must be positive definite")
    if dt is None:
        P = scipy.linalg.solve_continuous_are(A, B, Q, R)
        return np.linalg.solve(R, B.T @ P)
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = A, B
    phi = scipy.linalg.expm(block * dt)
    Ad, Bd = phi[:n, :n], phi[:n, n:]
    P = scipy.linalg.solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


class LQRPolicy:
    """``u = -K (x - x_ref)`` on the observed channels, in the environment's action units.

    Unobserved states are taken at their reference value (e.g. the USV's unmeasured sway speed):
    pass an estimator's full state instead (``observed=None``) to close that gap.

    :param K: gain on the full state (n_u x n_x).
    :param observed: indices of the states the observation holds, in order; None = full state.
    :param x_ref, u_ref: reference state and input (physical units).
    :param u_low, u_high: physical limits mapped to actions -1 and +1 (of the inputs, or of the
        actuators when ``allocation`` is given).
    :param allocation: ``(n_actuators, n_inputs)`` map from inputs to actuator commands (e.g. the
        pseudo-inverse of a thruster allocation matrix), or None when actions are the inputs.
    """

    def __init__(self, K: ArrayLike, observed: ArrayLike | None, x_ref: ArrayLike,
                 u_ref: ArrayLike, u_low: ArrayLike, u_high: ArrayLike,
                 allocation: ArrayLike | None = None) -> None:
        self.K = np.atleast_2d(np.asarray(K, dtype=float))
        idx = np.arange(self.K.shape[1]) if observed is None else np.asarray(observed)
        self.K_observed = self.K[:, idx]
        self.x_ref = np.asarray(x_ref, dtype=float)[idx]
        self.u_ref = np.asarray(u_ref, dtype=float)
        self.u_mid = (np.asarray(u_high) + np.asarray(u_low)) / 2
        self.u_half = (np.asarray(u_high) - np.asarray(u_low)) / 2
        self.allocation = None if allocation is None else np.asarray(allocation, dtype=float)

    @classmethod
    def for_env(cls, env: Any, observed: str | None = "sensors") -> LQRPolicy:
        """The discrete LQR of a marine environment's model, task weights and control period.

        :param observed: ``"sensors"`` (the env's measured channels) or None (full state, for
            ``info["state"]`` or an estimator's output).
        """
        sim = env.unwrapped.sim
        A, B, _ = sim.model.linearize(sim.task.x_ref, sim.task.u_ref)
        # states that are not weighed and drive nothing (e.g. a position when only the heading
        # matters) are left out: kept, their undamped modes would make the Riccati equation
        # unsolvable, and the gain on them would be zero anyway
        keep = np.flatnonzero((sim.task.q > 0) | np.any(A != 0, axis=0))
        K = np.zeros((B.shape[1], A.shape[0]))
        K[:, keep] = lqr_gain(A[np.ix_(keep, keep)], B[keep], np.diag(sim.task.q[keep]),
                              np.diag(sim.task.r), dt=sim.dt)
        idx = None
        if observed == "sensors":
            missing = sorted(set(sim.sensors.channels) - set(sim.model.state_names))
            if missing:
                raise ValueError(f"LQR on the sensors needs measured states; {missing} are "
                                 "not states: use an estimator and observed=None")
            idx = [sim.model.state_names.index(c) for c in sim.sensors.channels]
        act = sim.actuation
        allocation = None if act.matrix is None else np.linalg.pinv(act.matrix)
        return cls(K, idx, sim.task.x_ref, sim.task.u_ref, act.low, act.high, allocation)

    def predict(self, observation: ArrayLike, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[NDArray[np.float32], None]:
        """Actions in [-1, 1] for one observation or a batch (SB3's signature)."""
        obs = np.asarray(observation, dtype=float)
        u = self.u_ref - (obs - self.x_ref) @ self.K_observed.T
        if self.allocation is not None:
            u = u @ self.allocation.T
        action = np.clip((u - self.u_mid) / self.u_half, -1.0, 1.0)
        return action.astype(np.float32), None
