"""Kalman filters that carry a model of the vehicle's own disturbances.

A white-noise filter (:func:`~estimators.kalman.default_process_noise`) treats waves, current and
wind as independent from one control period to the next, so it trusts its model too long: a
current that has pushed the vehicle for a minute will push it for the next. Here every
disturbance channel of the environment gets the discrete model its source implies, and those
models' states are appended to the vehicle's:

* a Gauss-Markov channel (current, wind, gusts; :class:`~marine_envs.sea.processes.GaussMarkov`)
  its exact AR(1) sampling ``xi_{k+1} = a xi_k + w_k``, ``a = exp(-dt/T)``, ``Var w = std^2
  (1 - a^2)``; white (``T = 0``) channels stay process noise, constant ones (``std = 0``) are
  their mean;
* a wave channel (:class:`~marine_envs.sea.waves.WaveRealisation`) a second-order shaping filter,
  the AR(2) ``xi_{k+1} = phi_1 xi_k + phi_2 xi_{k-1} + w_k`` whose autocovariance at lags 0, 1, 2
  is the sea's own (Yule-Walker on a long realisation of the env's own sea, so a sea whose
  height varies in time is averaged over its schedule): its peak frequency and damping are
  :attr:`DisturbanceModel.wave_peaks`;
* a step event (the ROV's morph command; :class:`~marine_envs.sea.processes.StepEvent`) a random
  walk whose increments carry the jump's energy over its window.

The disturbances are held over each control period (as the environments apply them), so the
augmented model ``[x; xi]`` is discretised exactly: ``x_{k+1} = Phi x_k + Gamma_u u_k + Gamma_d
(mean + C xi_k) + c``. The model is linearised at the task's reference and the disturbances'
mean (a mean wind loads the hull; a white-noise filter linearised at no wind does not see it).
The measurement noise is the sensors' own (noise variance plus quantization step squared over
12, :func:`~estimators.kalman.default_measurement_noise`).

Two more terms come from the environment's own models rather than being set by hand:

* the **model error** of the linearisation: the covariance of the one-step errors of the linear
  model along a calibration run of the env's own simulator (its nonlinear equations, its
  disturbances, seeds of their own) regulated to the reference by the discrete LQR of the same
  linear model and the task's weights, the regime a controller keeps the vehicle in, with a
  margin (:data:`MODEL_ERROR_MARGIN`) for the wider excursions behind a filter (a filter that
  believed its linearisation exact would trust it through a manoeuvre, a morph or a start far
  from the reference);
* the **prior**: the mean and covariance of the env's own initial-state distribution (a filter
  told that a bias of tens of kN is known to within 1 N learns it for minutes).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from marine_envs.models import zoh
from marine_envs.models.linear import dlqr_gain
from marine_envs.sea.processes import GaussMarkov, Stacked, StepEvent
from marine_envs.sea.waves import WaveRealisation

from .kalman import (
    AdaptiveKalmanFilter,
    KalmanFilter,
    _output_matrix,
    _wrapped_channels,
    default_measurement_noise,
)

FloatArray = NDArray[np.float64]
#: Steps of the env's own sea sampled for each wave channel's autocovariance (several episodes'
#: worth, from fixed seeds: the same model every time).
WAVE_SAMPLE_STEPS, WAVE_SAMPLE_SEEDS = 8192, (0, 1, 2, 3)
#: The calibration run of the model error: boats (their seeds, apart from any evaluation's) and
#: steps; and the initial states drawn for the prior.
CALIBRATION_SEEDS, CALIBRATION_STEPS = tuple(range(900_000, 900_008)), 1000
PRIOR_DRAWS = 2000
#: The calibration run's regulator sees the true state; behind a filter, and more so behind
#: noisy sensors, the vehicle strays further and its linearisation errs more: the model error's
#: covariance is taken this many times the calibrated one (chosen on seeds 1000-1005 at noise x1
#: and x32: the ROV costs 608 -> 572 and 52190 -> 1333 under LQR; the others move < 0.3 %).
MODEL_ERROR_MARGIN = 10.0


@dataclasses.dataclass(frozen=True)
class DisturbanceModel:
    """The discrete model of a vehicle's disturbances ``d_k`` (held over step k)::

        xi_{k+1} = F xi_k + w_k,   w_k ~ N(0, Q)
        d_k      = mean + C xi_k + v_k,   v_k ~ N(0, white)   (the channels without memory)

    :ivar names: a name per state of ``xi`` (the disturbance channel's, ``_prev`` for the lag of
        a wave channel's AR(2)).
    :ivar P0: the covariance of ``xi`` at an episode's start (its stationary one, or 0 where
        the start is known).
    :ivar wave_peaks: ``{channel: (peak frequency rad/s, damping ratio)}`` of each wave channel's
        shaping filter (the AR(2)'s poles as a continuous second-order system).
    """

    F: FloatArray
    C: FloatArray
    Q: FloatArray
    P0: FloatArray
    mean: FloatArray
    white: FloatArray
    names: tuple[str, ...]
    wave_peaks: dict[str, tuple[float, float]]

    @property
    def size(self) -> int:
        """Number of disturbance-model states."""
        return len(self.names)


def disturbance_model(sim: Any) -> DisturbanceModel:
    """The :class:`DisturbanceModel` of a simulator's disturbance source (module docstring);
    a source of another kind is taken as white noise of its sampled covariance."""
    names = tuple(sim.model.disturbance_names)
    if sim.disturbances is None or not names:
        n = len(names)
        return _combine([], n, np.zeros(n), np.zeros((n, n)))
    return _model_of(sim.disturbances, names, sim.dt)


def _model_of(source: Any, names: Sequence[str], dt: float) -> DisturbanceModel:
    if isinstance(source, Stacked):
        parts, start = [], 0
        for part in source.sources:
            parts.append(_model_of(part, names[start:start + part.width], dt))
            start += part.width
        return _stack(parts)
    if isinstance(source, GaussMarkov):
        return _gauss_markov(source, names)
    if isinstance(source, StepEvent):
        return _step_event(source, names, dt)
    if isinstance(source, WaveRealisation):
        return _waves(source, names, dt)
    samples = _sample(source)
    return _combine([], len(names), samples.mean(axis=0),
                    np.atleast_2d(np.cov(samples, rowvar=False)))


# a channel's block of states: (their names, F block, the channel's index, Q block, P0 block)
_State = tuple[tuple[str, ...], FloatArray, int, FloatArray, FloatArray]


def _gauss_markov(source: GaussMarkov, names: Sequence[str]) -> DisturbanceModel:
    states: list[_State] = []
    white = np.zeros(len(names))
    for c, name in enumerate(names):
        a, std = float(source.a[c]), float(source.std[c])
        if std == 0.0:
            continue  # a constant: its mean
        if a == 0.0:
            white[c] = std**2  # no memory: process noise
            continue
        states.append(((name,), np.array([[a]]), c, np.array([[source.gain[c] ** 2]]),
                       np.array([[std**2]])))
    return _combine(states, len(names), source.mean, np.diag(white))


def _step_event(source: StepEvent, names: Sequence[str], dt: float) -> DisturbanceModel:
    """A random walk per channel that jumps: the jump's square spread over the steps of the
    window it falls in (or over the steps up to its fixed time); the start is known."""
    span = source.window[1] - source.window[0] if source.window is not None else source.time
    steps = max(float(span) / dt, 1.0)
    states: list[_State] = []
    for c, name in enumerate(names):
        jump = float(source.after[c] - source.before[c])
        if jump != 0.0:
            states.append(((name,), np.array([[1.0]]), c, np.array([[jump**2 / steps]]),
                           np.zeros((1, 1))))
    return _combine(states, len(names), source.before, np.zeros((len(names), len(names))))


def _waves(source: WaveRealisation, names: Sequence[str], dt: float) -> DisturbanceModel:
    """Each wave channel's AR(2) by Yule-Walker on the autocovariance of the env's own sea."""
    samples = [_sample(source, WAVE_SAMPLE_STEPS, seed) for seed in WAVE_SAMPLE_SEEDS]
    mean = np.mean([s.mean(axis=0) for s in samples], axis=0)
    states: list[_State] = []
    peaks: dict[str, tuple[float, float]] = {}
    for c, name in enumerate(names):
        r0, r1, r2 = np.mean([_autocovariance(s[:, c], 3) for s in samples], axis=0)
        if not r0 > 1e-12 * max(1.0, abs(mean[c])) ** 2:
            continue  # a channel this sea does not move
        det = r0 * r0 - r1 * r1
        phi1, phi2 = r1 * (r0 - r2) / det, (r0 * r2 - r1 * r1) / det
        innovation = max(r0 - phi1 * r1 - phi2 * r2, 1e-12 * r0)
        states.append(((name, f"{name}_prev"), np.array([[phi1, phi2], [1.0, 0.0]]), c,
                       np.diag([innovation, 0.0]), np.array([[r0, r1], [r1, r0]])))
        peaks[name] = _second_order(phi1, phi2, dt)
    model = _combine(states, len(names), mean, np.zeros((len(names), len(names))))
    return dataclasses.replace(model, wave_peaks=peaks)


def _second_order(phi1: float, phi2: float, dt: float) -> tuple[float, float]:
    """Peak frequency (rad/s) and damping ratio of the AR(2)'s poles ``z = exp(s dt)``."""
    s = np.log(np.roots([1.0, -phi1, -phi2]).astype(complex)) / dt
    wn = float(np.abs(s).max())
    return wn, float(-s.real.max() / wn) if wn > 0 else 1.0


def _sample(source: Any, steps: int = 2000, seed: int = 0) -> FloatArray:
    """One boat's realisation of a copy of ``source`` over ``steps`` steps (fixed seed)."""
    copy_ = copy.deepcopy(source)
    copy_.bind(1)
    boat = np.array([0])
    copy_.reset(boat, [np.random.default_rng(seed)])
    # a block at a time, as the source's stream refills (the rows its steps would hand out)
    chunks = [copy_.stream.blocks[0].copy()]
    while sum(map(len, chunks)) < steps:
        chunks.append(copy_.blocks(boat)[0])
    return np.concatenate(chunks)[:steps]


def _autocovariance(x: FloatArray, lags: int) -> FloatArray:
    x = x - x.mean()
    return np.array([x[:x.size - k] @ x[k:] / x.size for k in range(lags)])


def _combine(states: list[_State], n_channels: int, mean: Any, white: FloatArray
             ) -> DisturbanceModel:
    import scipy.linalg  # (here: `import estimators` need not load it)

    names = tuple(name for state in states for name in state[0])
    C = np.zeros((n_channels, len(names)))
    column = 0
    for state_names, _, channel, _, _ in states:
        C[channel, column] = 1.0  # the channel is the first state of its block
        column += len(state_names)
    F = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[1] for state in states))
    Q = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[3] for state in states))
    P0 = scipy.linalg.block_diag(np.zeros((0, 0)), *(state[4] for state in states))
    return DisturbanceModel(F, C, Q, P0, np.asarray(mean, dtype=float).copy(), white, names, {})


def _stack(parts: list[DisturbanceModel]) -> DisturbanceModel:
    """Models of consecutive channel groups side by side."""
    import scipy.linalg  # (here: `import estimators` need not load it)

    def diag(attr: str) -> FloatArray:
        return scipy.linalg.block_diag(np.zeros((0, 0)), *(getattr(p, attr) for p in parts))

    peaks = {k: v for p in parts for k, v in p.wave_peaks.items()}
    return DisturbanceModel(diag("F"), diag("C"), diag("Q"), diag("P0"),
                            np.concatenate([p.mean for p in parts]), diag("white"),
                            tuple(n for p in parts for n in p.names), peaks)


@dataclasses.dataclass(frozen=True)
class AugmentedSystem:
    """The discrete model ``[x; xi]`` of a vehicle and its disturbances, as
    :class:`~estimators.kalman.KalmanFilter` takes it (:meth:`filter_arguments`)."""

    F: FloatArray
    G: FloatArray
    H: FloatArray
    Q: FloatArray
    R: FloatArray
    c: FloatArray
    d: FloatArray
    x0: FloatArray
    P0: FloatArray
    dt: float
    state_names: tuple[str, ...]
    measurement_names: tuple[str, ...]
    angular: tuple[str, ...]
    disturbances: DisturbanceModel

    def filter_arguments(self) -> dict[str, Any]:
        """Keyword arguments of :class:`~estimators.kalman.KalmanFilter`."""
        return {"F": self.F, "G": self.G, "H": self.H, "Q": self.Q, "R": self.R, "dt": self.dt,
                "c": self.c, "d": self.d, "x0": self.x0, "P0": self.P0,
                "state_names": self.state_names, "measurement_names": self.measurement_names,
                "angular": self.angular}


def augmented_system(env: Any, model_error: bool = True, prior: bool = True
                     ) -> AugmentedSystem:
    """The vehicle of ``env`` (single or vector, possibly wrapped) and its disturbances' model,
    linearised at the task's reference and the disturbances' mean, discretised at the control
    period (module docstring).

    :param model_error: add the linearisation's model error to the process noise
        (:func:`model_error_covariance`; else only a floor).
    :param prior: start from the env's initial-state distribution (:func:`initial_prior`; else
        from the reference with unit covariance, as :class:`~estimators.kalman.KalmanFilter`).
    """
    import scipy.linalg  # (here: `import estimators` need not load it)

    sim = env.unwrapped.sim
    model, dt = sim.model, sim.dt
    dist = disturbance_model(sim)
    x_ref, u_ref = np.asarray(sim.task.x_ref, dtype=float), np.asarray(sim.task.u_ref, dtype=float)
    A, B, E = model.linearize(x_ref, u_ref, d0=dist.mean)
    n_x, n_u, n_xi = A.shape[0], B.shape[1], dist.size
    Phi, Gamma = zoh(A, np.column_stack([B, E, model.rhs(x_ref, u_ref, dist.mean)]), dt)
    G_u, G_d, drift = Gamma[:, :n_u], Gamma[:, n_u:-1], Gamma[:, -1]
    n = n_x + n_xi
    F = np.zeros((n, n))
    F[:n_x, :n_x], F[:n_x, n_x:], F[n_x:, n_x:] = Phi, G_d @ dist.C, dist.F
    G = np.vstack([G_u, np.zeros((n_xi, n_u))])
    c = np.concatenate([x_ref - Phi @ x_ref - G_u @ u_ref + drift, np.zeros(n_xi)])
    c_x = c[:n_x]
    Q_x = G_d @ dist.white @ G_d.T
    if model_error:
        Q_x = Q_x + MODEL_ERROR_MARGIN * model_error_covariance(sim, Phi, G_u, G_d, c_x,
                                                                dist.mean)
    # a floor keeps every state's prediction honest (per state, in its own unit)
    Q_x = (Q_x + Q_x.T) / 2 + np.diag(1e-9 * np.maximum(1.0, np.diag(Q_x)))
    Q = scipy.linalg.block_diag(Q_x, dist.Q)
    channels = tuple(sim.sensors.channels)
    H_x, d = _output_matrix(model, channels, x_ref)
    H = np.hstack([H_x, np.zeros((len(channels), n_xi))])
    x0_x, P0_x = initial_prior(sim) if prior else (x_ref, np.eye(n_x))
    angular = tuple(ch for ch, w in zip(channels, _wrapped_channels(sim), strict=True) if w)
    return AugmentedSystem(F, G, H, Q, default_measurement_noise(sim), c, d,
                           np.concatenate([x0_x, np.zeros(n_xi)]),
                           scipy.linalg.block_diag(P0_x, dist.P0), dt,
                           (*model.state_names, *dist.names), channels, angular, dist)


def initial_prior(sim: Any) -> tuple[FloatArray, FloatArray]:
    """Mean and covariance of the simulator's initial-state distribution (drawn from a fixed
    seed), with a floor per state in its own unit (a state drawn exactly is still estimated)."""
    rng = np.random.default_rng(PRIOR_DRAWS)
    draws = np.array([sim.initial_state(rng) for _ in range(PRIOR_DRAWS)])
    P0 = np.atleast_2d(np.cov(draws, rowvar=False))
    P0 = (P0 + P0.T) / 2 + np.diag(1e-6 * np.maximum(1.0, np.diag(P0)))
    return draws.mean(axis=0), P0


def model_error_covariance(sim: Any, Phi: FloatArray, G_u: FloatArray, G_d: FloatArray,
                           c: FloatArray, mean: FloatArray) -> FloatArray:
    """The second moment of the one-step errors of ``x_{k+1} = Phi x_k + G_u u_k + G_d (d_k -
    mean) + c`` along a calibration run of a copy of ``sim`` (:data:`CALIBRATION_SEEDS`, at
    most :data:`CALIBRATION_STEPS` steps, a boat's steps after it failed left out) under the
    discrete LQR of ``(Phi, G_u)`` with the task's weights (the nominal input where no LQR
    exists). The disturbances are the run's own, so what remains is the linearisation's
    error."""
    run = copy.deepcopy(sim)
    boats = len(CALIBRATION_SEEDS)
    run.bind(boats)
    run.reset(np.arange(boats), [np.random.default_rng(s) for s in CALIBRATION_SEEDS])
    gain = _regulator(sim, Phi, G_u)
    x_ref, u_ref = sim.task.x_ref, sim.task.u_ref
    matrix = sim.actuation.matrix
    to_actuators = None if matrix is None else np.linalg.pinv(matrix)
    running = np.ones(boats, dtype=bool)
    errors = []
    for _ in range(CALIBRATION_STEPS):
        x = run.x
        u = np.broadcast_to(u_ref, (boats, u_ref.size)) if gain is None else \
            u_ref - (x - x_ref) @ gain.T
        f = u if to_actuators is None else u @ to_actuators.T
        action = np.clip((f - run.u_mid) / run.u_scale, -1.0, 1.0)
        _, _, failed = run.step(action, measure=False)
        predicted = x @ Phi.T + run.u @ G_u.T + (run.d - mean) @ G_d.T + c
        errors.append((run.x - predicted)[running])
        running &= ~failed
        if not running.any():
            break
    e = np.concatenate(errors)
    return e.T @ e / max(len(e), 1)


def _regulator(sim: Any, Phi: FloatArray, G_u: FloatArray) -> FloatArray | None:
    """The discrete LQR gain of ``(Phi, G_u)`` with the task's weights (the design of
    :class:`agents.lqr.LQRPolicy`, discounted a little more: a calibration regulator need only
    keep the boats near the reference); None where no design exists."""
    try:
        return dlqr_gain(Phi, G_u, sim.task.q, sim.task.r, discount=0.999)
    except ValueError:
        return None


def disturbance_filter(env: Any, adaptive: bool = False, adaptive_ratio: float = 10.0,
                       model_error: bool = True, prior: bool = True,
                       **kwargs: Any) -> KalmanFilter:
    """A Kalman filter of ``env``'s vehicle and its disturbances (:func:`augmented_system`);
    with ``adaptive``, the hydrofoil AKF paper's adaptive filter on top of it (process noise
    switched between the model's and ``adaptive_ratio`` times it).

    :param model_error, prior: see :func:`augmented_system`.
    :param kwargs: passed to the filter (``batch_size``, ``divergence_ratio``, ...).
    """
    system = augmented_system(env, model_error, prior)
    arguments = {**system.filter_arguments(), **kwargs}
    if adaptive:
        return AdaptiveKalmanFilter(**arguments, Q_max=adaptive_ratio * system.Q)
    return KalmanFilter(**arguments)


__all__ = ["AugmentedSystem", "DisturbanceModel", "augmented_system", "disturbance_filter",
           "disturbance_model", "initial_prior", "model_error_covariance"]
