"""LQR from a model's linearisation, acting on whatever the environment observes.

The designs (``lqr``, ``dlqr``, ``lqr_integral``, ``zoh``) are the project's one copy in
:mod:`marine_envs.models.linear`, re-exported here; its conventions are python-control's:
``u = u_ref - K (x - x_ref)``, the discrete design on the zero-order-hold (ZOH) model with period
``dt``. The environments' stage cost is exactly the discrete one (same Q, R), so LQR and RL
agents are compared on one number.

Behind a Kalman filter that carries its disturbances' models (``estimators.disturbance``: waves,
current, wind as states of their own), the design is the LQR of that augmented model: the
disturbance states are not controllable, so the gain on them is the feed-forward that meets a
predicted wave or gust instead of waiting for the error it makes (LQG with a disturbance model;
:meth:`LQRPolicy.for_env`'s ``feedforward``).

Integral action augments the state with ``z`` per integrated state ``i``:
``z_{k+1} = z_k + dt (x_i - x_ref_i)``, and ``u = u_ref - K_x (x - x_ref) - K_z z``; it removes
the steady offset a constant disturbance leaves. The policy keeps ``z`` per batch row, with
conditional integration as anti-windup.

:class:`LQRPolicy` has Stable-Baselines3's ``predict`` signature, so one evaluation loop runs LQR
and SB3 policies.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.envs.system import System, folded_action_map
from marine_envs.models.linear import (
    LQRSolution,
    check_matrix,
    check_period,
    dlqr,
    dlqr_gain,
    lqr,
    lqr_gain,
    lqr_integral,
    zoh,
)

FloatArray = NDArray[np.float64]
Observed = Literal["auto", "sensors", "state"] | None


# -- the policy ----------------------------------------------------------------------------------
class LQRPolicy:
    """``u = u_ref - K (x - x_ref) - K_i z`` on the observed channels, as normalised actions.

    Unobserved states are taken at their reference value (e.g. the USV's unmeasured sway speed):
    give the policy a full state (true, or an estimator's) to close that gap.

    :param K: gain on the full state, ``(n_u, n_x)``, input units per state unit.
    :param observed: indices of the states the observation holds, in order; None = the full state.
    :param x_ref: reference state, ``(n_x,)``, state units.
    :param u_ref: input at the reference, ``(n_u,)``, input units.
    :param u_low, u_high: physical limits mapped to actions -1 and +1 (of the inputs, or of the
        actuators when ``allocation`` is given), their units.
    :param allocation: ``(n_actuators, n_u)`` map from inputs to actuator commands (e.g. the
        pseudo-inverse of a thruster allocation matrix), or None when actions are the inputs.
    :param integral: indices of the integrated states (each must be observed), or None.
    :param K_i: gain on the integral states, ``(n_u, n_z)``, input units per (state unit * s).
    :param dt: period between :meth:`predict` calls, s (the integration step; needed with
        ``integral``).
    :param anti_windup: conditional integration: a row's integral state is not advanced while
        that would push an already saturated action further out.
    :param observation_size: width of the observation (default: ``len(observed)``); columns after
        the observed states are ignored (e.g. parameters an estimator appends).
    """

    def __init__(self, K: ArrayLike, observed: ArrayLike | None, x_ref: ArrayLike,
                 u_ref: ArrayLike, u_low: ArrayLike, u_high: ArrayLike,
                 allocation: ArrayLike | None = None, *, integral: ArrayLike | None = None,
                 K_i: ArrayLike | None = None, dt: float | None = None,
                 anti_windup: bool = True, observation_size: int | None = None) -> None:
        self.K = check_matrix("K", K)
        n_u, n_x = self.K.shape
        idx = np.arange(n_x) if observed is None else np.asarray(observed, dtype=int).reshape(-1)
        if idx.size == 0 or len(set(idx.tolist())) != idx.size or idx.min() < 0 or \
                idx.max() >= n_x:
            raise ValueError(f"observed={np.asarray(observed).tolist()} is invalid: distinct "
                             f"state indices in [0, {n_x})")
        self.observed = idx
        self.x_ref_full = _vector("x_ref", x_ref, n_x)
        self.u_ref = _vector("u_ref", u_ref, n_u)
        self.allocation = None if allocation is None else check_matrix("allocation", allocation)
        n_a = n_u if self.allocation is None else self.allocation.shape[0]
        if self.allocation is not None and self.allocation.shape[1] != n_u:
            raise ValueError(f"allocation has shape {self.allocation.shape}; expected "
                             f"(n_actuators, {n_u})")
        low, high = _vector("u_low", u_low, n_a), _vector("u_high", u_high, n_a)
        if not np.all(low < high):
            raise ValueError(f"u_low={low.tolist()} and u_high={high.tolist()} are invalid: "
                             "each low < high")
        self.observation_size = idx.size if observation_size is None else int(observation_size)
        if self.observation_size < idx.size:
            raise ValueError(f"observation_size={observation_size} is smaller than the "
                             f"{idx.size} observed states")
        self.x_ref = self.x_ref_full[idx]

        # the whole affine map to normalised actions, precomputed: v = c - e G' - z H'
        to_action, offset = folded_action_map(low, high, self.allocation)
        self._c = to_action @ self.u_ref + offset
        self.K_observed = self.K[:, idx]
        self._G = to_action @ self.K_observed

        self.integral = np.zeros(0, dtype=int) if integral is None else \
            np.asarray(integral, dtype=int).reshape(-1)
        n_z = self.integral.size
        self.K_i = np.zeros((n_u, 0)) if K_i is None else check_matrix("K_i", K_i)
        if self.K_i.shape != (n_u, n_z):
            raise ValueError(f"K_i has shape {self.K_i.shape}; expected ({n_u}, {n_z}), one "
                             "column per integrated state")
        missing = sorted(set(self.integral.tolist()) - set(idx.tolist()))
        if missing:
            raise ValueError(f"integral action on state(s) {missing} needs them observed; "
                             f"observed: {idx.tolist()}")
        self.dt = None if n_z == 0 and dt is None else check_period(dt)
        self._integral_columns = np.array([idx.tolist().index(i) for i in self.integral],
                                          dtype=int)
        self._H = to_action @ self.K_i
        self.anti_windup = bool(anti_windup)
        #: integral states ``z``, ``(N, n_z)`` (state unit * s), allocated at the first predict
        self.integral_state: FloatArray | None = None

    @classmethod
    def for_model(cls, model: Any, Q: ArrayLike | Mapping[str, float],
                  R: ArrayLike | Mapping[str, float], *, dt: float | None = None,
                  continuous: bool = False, x_ref: ArrayLike | None = None,
                  u_ref: ArrayLike | None = None, u_low: ArrayLike | None = None,
                  u_high: ArrayLike | None = None, allocation: ArrayLike | None = None,
                  integral: Mapping[str, float] | None = None,
                  observed: Sequence[str | int] | None = None,
                  observation_size: int | None = None, anti_windup: bool = True) -> LQRPolicy:
        """LQR of any model of the vehicle-model protocol, linearised at ``(x_ref, u_ref)``.

        States that are not weighted and appear nowhere in ``A`` (e.g. a position when only the
        heading matters) are left out of the design: their undamped modes would make the Riccati
        equation unsolvable, and their gain would be zero anyway.

        :param model: has ``state_names``, ``input_names``, ``x0``, ``u0``, ``u_bounds`` and
            ``linearize(x0, u0) -> (A, B, E)``.
        :param Q: state weight, ``(n_x, n_x)``, its diagonal ``(n_x,)``, or ``{state: weight}``
            (1/state unit^2).
        :param R: input weight, ``(n_u, n_u)``, ``(n_u,)`` or ``{input: weight}``.
        :param dt: control period, s; None = continuous design (then no integral action).
        :param continuous: with ``dt``, use the continuous gain at period ``dt`` (a sampled
            continuous design) instead of the discrete LQR of the ZOH model.
        :param x_ref, u_ref: reference state and input (default: the model's ``x0``, ``u0``).
        :param u_low, u_high: limits mapped to actions -1, +1 (default: ``model.u_bounds``;
            required with ``allocation``).
        :param allocation: ``(n_actuators, n_u)`` input-to-actuator map, or None.
        :param integral: ``{state name: weight of its integral state}`` for integral action.
        :param observed: names (or indices) of the states the observation holds; None = all.
        :param observation_size: see :class:`LQRPolicy`.
        :param anti_windup: see :class:`LQRPolicy`.
        """
        names, inputs = tuple(model.state_names), tuple(model.input_names)
        n, m = len(names), len(inputs)
        x_ref = np.asarray(model.x0, float) if x_ref is None else _vector("x_ref", x_ref, n)
        u_ref = np.asarray(model.u0, float) if u_ref is None else _vector("u_ref", u_ref, m)
        Q = _weights("Q", Q, names)
        R = _weights("R", R, inputs)
        if dt is not None:
            dt = check_period(dt)
        integrated, weights = _integral_spec(integral, names)
        if integrated.size and dt is None:
            raise ValueError("integral action needs dt, the period between predict calls (s)")
        observed_idx = _indices("observed", observed, names)
        if observed_idx is not None:
            missing = [names[i] for i in integrated if i not in observed_idx]
            if missing:
                raise ValueError(f"integral action on {missing} needs them observed; observed: "
                                 f"{[names[i] for i in observed_idx]}")
        A, B, _ = model.linearize(x_ref, u_ref)
        A, B = np.asarray(A, float), np.asarray(B, float)
        keep = np.flatnonzero(np.any(Q != 0, axis=0) | np.any(A != 0, axis=0))
        keep = np.union1d(keep, integrated)
        sub = np.ix_(keep, keep)
        design_dt = None if continuous else dt
        position = np.searchsorted(keep, integrated)  # integrated states in the reduced design
        try:
            if integrated.size:
                gain = lqr_integral(A[sub], B[keep], Q[sub], R, position, weights,
                                    dt=design_dt).K
            else:
                gain = lqr(A[sub], B[keep], Q[sub], R, dt=design_dt).K
        except ValueError as error:
            # the design's indices are of the reduced state, then the integrals: name them
            design = [names[i] for i in keep] + [f"integral of {names[i]}" for i in integrated]
            raise ValueError(f"LQR of {getattr(model, 'name', type(model).__name__)!r} "
                             f"(design states {design}): {error}") from None
        K = np.zeros((m, n))
        K[:, keep] = gain[:, :keep.size]
        if allocation is not None and (u_low is None or u_high is None):
            raise ValueError("with an allocation, give u_low and u_high (the actuator limits)")
        low, high = model.u_bounds if u_low is None or u_high is None else (u_low, u_high)
        return cls(K, observed_idx, x_ref, u_ref, low, high,
                   allocation, integral=integrated if integrated.size else None,
                   K_i=gain[:, keep.size:] if integrated.size else None, dt=dt,
                   anti_windup=anti_windup, observation_size=observation_size)

    @classmethod
    def for_augmented(cls, F: ArrayLike, G: ArrayLike, q: ArrayLike, r: ArrayLike, *,
                      x_ref: ArrayLike, u_ref: ArrayLike, u_low: ArrayLike, u_high: ArrayLike,
                      allocation: ArrayLike | None = None, dt: float | None = None,
                      discount: float = 0.9999) -> LQRPolicy:
        """The discrete LQR of ``x_{k+1} = F x_k + G u_k`` (e.g. a Kalman filter's model of a
        vehicle and its disturbances), every state observed.

        Designed by :func:`~marine_envs.models.linear.dlqr_gain` (the states that are weighted
        or move another; a discount just below one lets a random-walk disturbance pass, whose
        feed-forward gain is then still designed).

        :param q, r: diagonal state and input weights (unweighted disturbance states: 0).
        :param x_ref: reference of every state (disturbance states: 0, their mean).

        Other parameters as :meth:`for_model`.
        """
        K = dlqr_gain(F, G, q, r, discount)
        return cls(K, None, x_ref, u_ref, u_low, u_high, allocation, dt=dt)

    @classmethod
    def for_env(cls, env: Any, observed: Observed = "auto", *,
                integral: Mapping[str, float] | None = None, continuous: bool = False,
                anti_windup: bool = True, feedforward: bool = True) -> LQRPolicy:
        """The LQR of a marine environment's model, task weights and control period.

        :param env: a marine environment (single or native vector), possibly wrapped.
        :param observed: what :meth:`predict` will be given:

            * ``"sensors"``: the environment's observation (its measured channels, which must
              be states);
            * ``"state"`` or None: the full model state (e.g. ``info["state"]``);
            * ``"auto"``: if the environment or a wrapper around it has an ``estimator``
              (whose ``state_names`` start with the model's), its observation is the estimate
              and the first ``n_x`` entries are used; else ``"sensors"``.
        :param integral: ``{state name: weight}`` for integral action (see :meth:`for_model`).
        :param continuous: apply the continuous LQR gain at the environment's period instead of
            the discrete LQR of the ZOH model (to compare with continuous designs).
        :param anti_windup: see :class:`LQRPolicy`.
        :param feedforward: behind a Kalman filter with disturbance states (``observed``
            ``"auto"``, no ``integral``, not ``continuous``), design on the filter's augmented
            model (:meth:`for_augmented`): feed-forward of the estimated disturbances.
        :raises ValueError: unknown ``observed``; sensors that are not states (use an
            estimator); an estimator whose states are not the model's.
        """
        system = env.unwrapped.system
        names = tuple(system.model.state_names)
        space = getattr(env, "single_observation_space", None)
        space = env.observation_space if space is None else space
        width = int(np.prod(space.shape)) if space.shape else None
        if observed not in ("auto", "sensors", "state", None):
            raise ValueError(f"observed={observed!r} is invalid: 'auto', 'sensors', 'state' or "
                             "None")
        idx: list[int] | None = None
        size: int | None = None
        if observed == "auto":
            estimator = _find_estimator(env)
            if estimator is not None:
                estimated = tuple(estimator.state_names)
                if estimated[:len(names)] != names:
                    raise ValueError(f"the estimator's states {list(estimated)} do not start "
                                     f"with the model's {list(names)}: LQR cannot read the "
                                     "estimate")
                if feedforward and not integral and not continuous:
                    policy = _with_disturbances(system, estimator)
                    if policy is not None:
                        return policy
                observed, size = "state", width
            else:
                observed = "sensors"
        if observed == "sensors":
            channels = system.channels
            missing = [c for c in channels if c not in names]
            if missing:
                raise ValueError(f"LQR on the sensors needs measured states; {missing} are not "
                                 "states: wrap the environment in an estimator "
                                 "(EstimatorWrapper, observed='auto') or feed the full state "
                                 "(observed='state')")
            idx = [names.index(c) for c in channels]
        return cls.for_system(system, idx, integral=integral, continuous=continuous,
                              anti_windup=anti_windup, observation_size=size)

    @classmethod
    def for_system(cls, system: System, observed: Sequence[str | int] | None = None, *,
                   integral: Mapping[str, float] | None = None, continuous: bool = False,
                   anti_windup: bool = True, observation_size: int | None = None) -> LQRPolicy:
        """The LQR of a system's model (``env.unwrapped.system``), linearised at its task's
        reference, with the task's weights, control period and actuators (thrusters through
        the least-squares allocation).

        :param observed: names (or indices) of the states the observation holds; None = all.

        Other parameters as :meth:`for_model`.
        """
        task, act = system.task, system.actuation
        return cls.for_model(system.model, np.diag(task.q), np.diag(task.r), dt=system.dt,
                             continuous=continuous, x_ref=task.x_ref, u_ref=task.u_ref,
                             u_low=act.low, u_high=act.high, allocation=act.to_actuators,
                             integral=integral, observed=observed,
                             observation_size=observation_size, anti_windup=anti_windup)

    # -- SB3's interface -------------------------------------------------------------------------
    def predict(self, observation: ArrayLike, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[NDArray[np.float32], None]:
        """Actions in [-1, 1] for one observation ``(n_obs,)`` or a batch ``(N, n_obs)``.

        :param observation: observed states (see ``observed``), their units.
        :param state: ignored (SB3's recurrent state; the integral states live in the policy).
        :param episode_start: ``(N,)`` booleans (or one for all rows): rows starting an episode,
            whose integral states are reset before acting (SB3's semantics).
        :param deterministic: ignored (LQR is deterministic).
        :return: ``(actions, None)``, actions float32 of shape ``(n_actuators,)`` or
            ``(N, n_actuators)``.
        """
        obs = np.asarray(observation, dtype=float)
        single = obs.ndim == 1
        x = obs[None] if single else obs
        if x.ndim != 2 or x.shape[1] != self.observation_size:
            raise ValueError(f"observation has shape {obs.shape}; expected "
                             f"({self.observation_size},) or (N, {self.observation_size})")
        if not np.isfinite(x).all():
            raise ValueError("observation contains NaN or inf")
        error = x[:, :self.observed.size] - self.x_ref
        v = self._c - error @ self._G.T
        if self.integral.size:
            z = self._integrator(x.shape[0], episode_start)
            v -= z @ self._H.T
            step = self.dt * error[:, self._integral_columns]
            if self.anti_windup:
                # integrating z_j moves action a by -H[a, j] * step_j: hold z_j in a row where
                # that pushes an action that is already beyond its limit further out
                beyond = np.sign(v) * (np.abs(v) > 1.0)
                deeper = (beyond[:, :, None] * -self._H[None] * step[:, None, :] > 0).any(axis=1)
                step[deeper] = 0.0
            z += step
        action = np.clip(v, -1.0, 1.0).astype(np.float32)
        return (action[0] if single else action), None

    def reset(self, idx: ArrayLike | None = None) -> None:
        """Zero the integral states of rows ``idx``; None = all (the batch is then sized anew
        at the next :meth:`predict`)."""
        if idx is None or self.integral_state is None:
            self.integral_state = None
            return
        self.integral_state[np.asarray(idx)] = 0.0

    def _integrator(self, batch: int, episode_start: Any) -> FloatArray:
        if self.integral_state is None:
            self.integral_state = np.zeros((batch, self.integral.size))
        elif self.integral_state.shape[0] != batch:
            raise ValueError(f"predict got {batch} observation(s) but the integral states hold "
                             f"{self.integral_state.shape[0]} row(s): call reset() first")
        if episode_start is not None:
            flags = np.asarray(episode_start, dtype=bool).reshape(-1)
            if flags.size not in (1, batch):
                raise ValueError(f"episode_start has {flags.size} entries; expected {batch} "
                                 "(one per observation) or 1")
            self.integral_state[np.broadcast_to(flags, (batch,))] = 0.0
        return self.integral_state


# -- helpers -------------------------------------------------------------------------------------
def _vector(name: str, value: ArrayLike, n: int) -> FloatArray:
    a = np.asarray(value, dtype=float).reshape(-1)
    if a.shape != (n,):
        raise ValueError(f"{name} has {a.size} entries; expected {n}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}={a.tolist()} has non-finite entries")
    return a


def _weights(name: str, value: ArrayLike | Mapping[str, float],
             names: tuple[str, ...]) -> FloatArray:
    """A weight matrix from a matrix, its diagonal, or ``{name: weight}`` (diagonal)."""
    n = len(names)
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - set(names))
        if unknown:
            raise ValueError(f"{name}: unknown name(s) {unknown}; known: {', '.join(names)}")
        value = [float(value.get(k, 0.0)) for k in names]
    a = np.asarray(value, dtype=float)
    if a.ndim == 1 and a.size == n:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"{name} has shape {a.shape}; expected ({n}, {n}) or ({n},) for "
                         f"{', '.join(names)}")
    return a


def _indices(name: str, value: Sequence[str | int] | None,
             names: tuple[str, ...]) -> list[int] | None:
    if value is None:
        return None
    out = []
    for v in value:
        if isinstance(v, str):
            if v not in names:
                raise ValueError(f"{name}: unknown state {v!r}; known: {', '.join(names)}")
            out.append(names.index(v))
        else:
            out.append(int(v))
    return out


def _integral_spec(integral: Mapping[str, float] | None,
                   names: tuple[str, ...]) -> tuple[NDArray[np.intp], FloatArray]:
    """Indices of the integrated states and their weights, in the model's state order."""
    if integral is None or len(integral) == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0)
    if not isinstance(integral, Mapping):
        raise TypeError(f"integral={integral!r} is invalid: a mapping {{state name: weight}}")
    unknown = sorted(set(integral) - set(names))
    if unknown:
        raise ValueError(f"integral: unknown state(s) {unknown}; known: {', '.join(names)}")
    chosen = [k for k in names if k in integral]
    weights = np.array([float(integral[k]) for k in chosen])
    if not np.all(np.isfinite(weights) & (weights > 0)):
        raise ValueError(f"integral={dict(integral)!r} is invalid: weights must be finite and "
                         "> 0")
    return np.array([names.index(k) for k in chosen], dtype=np.intp), weights


def _with_disturbances(system: System, estimator: Any) -> LQRPolicy | None:
    """:meth:`LQRPolicy.for_augmented` on a Kalman filter's model of the vehicle and its
    disturbance states; None when the estimator is no such filter (or no design exists)."""
    from estimators.kalman import KalmanFilter

    n_x = len(system.model.state_names)
    if not isinstance(estimator, KalmanFilter) or len(estimator.state_names) == n_x:
        return None
    n = len(estimator.state_names)
    task, act = system.task, system.actuation
    try:
        return LQRPolicy.for_augmented(
            estimator.F.astype(float), estimator.G.astype(float),
            np.concatenate([task.q, np.zeros(n - n_x)]), task.r,
            x_ref=np.concatenate([task.x_ref, np.zeros(n - n_x)]), u_ref=task.u_ref,
            u_low=act.low, u_high=act.high, allocation=act.to_actuators, dt=system.dt)
    except ValueError:
        return None


def _find_estimator(env: Any) -> Any:
    """The ``estimator`` of the environment or of any wrapper in its chain, or None."""
    seen = set()
    while env is not None and id(env) not in seen:
        seen.add(id(env))
        estimator = getattr(env, "estimator", None)
        if estimator is not None and hasattr(estimator, "state_names"):
            return estimator
        env = getattr(env, "env", None)
    return None


__all__ = ["LQRPolicy", "LQRSolution", "dlqr", "dlqr_gain", "lqr", "lqr_gain", "lqr_integral",
           "zoh"]
