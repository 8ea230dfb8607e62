"""What a Kalman filter of a vehicle is made of: its model linearised and discretised, and the
noise of its environment (the builders behind :meth:`KalmanFilter.from_model
<estimators.kalman.KalmanFilter.from_model>` and :meth:`~estimators.kalman.KalmanFilter.for_env`,
also used by the other filters).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel, zoh
from marine_envs.sensors import GaussianNoise, Quantizer, WrapAngle

from ..base import check_covariance

FloatArray = NDArray[np.floating]


def held_noise_covariance(A: ArrayLike, E: ArrayLike, dt: float,
                          disturbance_cov: ArrayLike) -> NDArray[np.float64]:
    """Process-noise covariance ``Q = Gamma_E Sigma Gamma_E'`` of disturbances ``d`` held over
    each period (``Gamma_E``: the :func:`~marine_envs.models.zoh` input matrix of ``E``), with
    ``Sigma`` their covariance."""
    E = np.atleast_2d(np.asarray(E, dtype=float))
    _, gamma = zoh(A, E, dt)
    sigma = check_covariance("disturbance_cov", disturbance_cov, E.shape[1])
    q = gamma @ sigma @ gamma.T
    return (q + q.T) / 2


def _wrap(a: FloatArray) -> FloatArray:
    """Angles ``a`` (rad) wrapped to (-pi, pi]."""
    return math.pi - (math.pi - a) % (2 * math.pi)


def linearised_model(model: VehicleModel, dt: float, measured: Sequence[str],
                     x_ref: NDArray[np.float64], u_ref: NDArray[np.float64]
                     ) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """``(F, G, H, c, d)`` of ``model`` linearised about ``(x_ref, u_ref)`` and discretised with a
    zero-order hold over ``dt`` s, in the model's absolute units: ``x_{k+1} ~= F x_k + G u_k + c``
    and ``output[measured] ~= H x + d``."""
    A, B, _ = model.linearize(x_ref, u_ref)
    Phi, Gamma = zoh(A, np.column_stack([B, model.rhs(x_ref, u_ref)]), dt)
    G, drift = Gamma[:, :-1], Gamma[:, -1]
    c = x_ref - Phi @ x_ref - G @ u_ref + drift
    H, d = _output_matrix(model, measured, x_ref)
    return Phi, G, H, c, d


def wrapped_channel_names(system: Any) -> list[str]:
    """The channels of the environment's sensors that are angles wrapped to (-pi, pi]."""
    return [c for c, w in zip(system.sensors.channels, _wrapped_channels(system), strict=True) if w]


def _output_matrix(model: VehicleModel, measured: Sequence[str],
                   x_ref: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """``(H, d)`` with ``output[measured] ~= H x + d`` near ``x_ref`` (exact for linear outputs)."""
    unknown = sorted(set(measured) - set(model.output_names))
    if unknown:
        raise ValueError(f"measured channel(s) {unknown} are not outputs of model "
                         f"{model.name!r}: {', '.join(model.output_names)}")
    rows = [model.output_names.index(c) for c in measured]
    if model.output_names == model.state_names:
        H = np.eye(len(x_ref))[rows]
        return H, np.zeros(len(rows))
    steps = 1e-6 * np.maximum(1.0, np.abs(x_ref))
    plus = model.output(x_ref + np.diag(steps))[:, rows]
    minus = model.output(x_ref - np.diag(steps))[:, rows]
    H = ((plus - minus) / (2 * steps[:, None])).T
    return H, model.output(x_ref[None])[0, rows] - H @ x_ref


def _wrapped_channels(system: Any) -> list[bool]:
    wrapped = np.zeros(len(system.sensors.channels), dtype=bool)
    for stage in system.sensors.stages:
        if isinstance(stage, WrapAngle):
            wrapped[stage.idx] = True
    return wrapped.tolist()


def default_measurement_noise(system: Any) -> NDArray[np.float64]:
    """Each channel's noise variance plus its quantization step squared over 12 (diagonal)."""
    var = np.zeros(len(system.sensors.channels))
    for stage in system.sensors.stages:
        if isinstance(stage, GaussianNoise):
            var += np.asarray(stage.std, dtype=float).ravel() ** 2
        elif isinstance(stage, Quantizer):
            var[stage.idx] += stage.mu[0] ** 2 / 12
    floor = 1e-12 * max(1.0, var.max())
    return np.diag(np.maximum(var, floor))


def default_process_noise(system: Any, steps: int = 2000, seed: int = 0) -> NDArray[np.float64]:
    """The covariance of the environment's disturbances over one ``steps``-long run of a fixed
    seed, held over each control period and mapped through the model's ``E`` at the reference."""
    model = system.model
    n_d = len(model.disturbance_names)
    A, _, E = model.linearize(system.task.x_ref, system.task.u_ref)
    if system.disturbances is None or n_d == 0:
        sigma = np.zeros((n_d, n_d))
    else:
        source = copy.deepcopy(system.disturbances)
        source.bind(1)
        source.reset(np.array([0]), [np.random.default_rng(seed)])
        samples = np.concatenate([source.step() for _ in range(steps)])
        sigma = np.atleast_2d(np.cov(samples, rowvar=False))
    n = A.shape[0]
    Q = held_noise_covariance(A, E, system.dt, sigma) if n_d else np.zeros((n, n))
    # a floor keeps every state's prediction honest about the model's own errors; per state, in
    # its own unit (a trace would mix N^2 of a bias with rad^2 of a heading)
    return Q + np.diag(1e-9 * np.maximum(1.0, np.diag(Q)))
