"""Step 1 of a diagnosis: the state the nominal model believes, and what it cannot explain.

The nominal model's extended Kalman filter and Rauch-Tung-Striebel smoother estimate every state,
measured or not, over the whole record. Their process noise is first guessed from the data, then
set to what the model actually fails to explain (one expectation-maximisation-like pass), so the
smoothed states follow the recording and the model's mistakes land in the *equation errors*:

    e_k = (x_{k+1} - Phi(x_k, u_k)) / dt

(``Phi``: one RK4 step of the nominal model). A term the model leaves out shows up in ``e`` as a
function of the smoothed states and inputs, which is what the hypotheses are fitted to.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from marine_envs.effects import rk4
from marine_envs.models import VehicleModel
from marine_envs.recording import Recording

from ..ekf import ExtendedKalmanFilter
from .innovations import Innovations

FloatArray = NDArray[np.float64]
#: Channels that are angles: unwrapped before smoothing.
ANGLES = ("psi", "phi", "theta", "psi_lf")
#: Unmeasured states get this share of their guessed process noise: they follow the model, so a
#: model error cannot hide in them and shows in the equations of the measured states instead.
FOLLOW_MODEL = 1e-3


@dataclass
class Residuals:
    """The nominal model's view of a recording.

    :param time: ``(T,)`` s.  :param dt: sample period, s.
    :param u: commanded inputs ``(T, n_u)``.  :param y: measurements ``(T, m)`` (angles unwrapped).
    :param channels: measured channel names; ``channel_index`` their indices among the outputs.
    :param x: smoothed states ``(T, n)``.  :param x_std: their standard deviations.
    :param error: equation errors ``(T - 1, n)``, state units per second.
    :param noise: white-noise standard deviation of each channel, estimated from the data.
    :param observable: per state, whether the measured channels see it.
    :param innovations: the last pass's filter innovations and their sensitivities.
    """

    model: VehicleModel
    time: FloatArray
    dt: float
    u: FloatArray
    y: FloatArray
    channels: tuple[str, ...]
    x: FloatArray
    x_std: FloatArray
    error: FloatArray
    noise: FloatArray
    observable: NDArray[np.bool_]
    substeps: int = 1
    innovations: Innovations | None = None

    @property
    def midpoint(self) -> FloatArray:
        """The state halfway through each step ``(T - 1, n)``: where equation errors are
        evaluated (a first-order-accurate match of the RK4 step)."""
        return 0.5 * (self.x[1:] + self.x[:-1])


def rk4_step(model: VehicleModel, x: FloatArray, u: FloatArray, dt: float,
             substeps: int = 1) -> FloatArray:
    """One step of ``dt`` for every row of ``x`` with inputs ``u`` held (no disturbance)."""
    def f(z, _t):
        return model.rhs(z, u)

    for _ in range(substeps):
        x = rk4(f, x, 0.0, dt / substeps)
    return x


def substeps_for(model: VehicleModel, dt: float) -> int:
    """RK4 steps per sample that keep the fastest mode of the linearised model accurate
    (``|lambda| h <= 0.5``; one step of 0.1 s is unstable for the hydrofoil's 38 1/s mode)."""
    A, _, _ = model.linearize()
    fastest = float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
    return max(1, math.ceil(fastest * dt / 0.5))


def equation_error(model: VehicleModel, x: FloatArray, u: FloatArray, dt: float,
                   substeps: int = 1) -> FloatArray:
    """``(x_{k+1} - Phi(x_k, u_k)) / dt``, shape ``(T - 1, n)``."""
    return (x[1:] - rk4_step(model, x[:-1], u[:-1], dt, substeps)) / dt


def white_noise_std(y: FloatArray) -> FloatArray:
    """Per column, the standard deviation of white noise on a smooth signal: from the fourth
    differences (a white sequence's have variance 70 sigma^2; a signal sampled well above its
    bandwidth contributes almost nothing), with a robust (median) scale."""
    d4 = np.diff(y, n=4, axis=0)
    mad = np.median(np.abs(d4 - np.median(d4, axis=0)), axis=0) / 0.6745
    return np.maximum(mad / np.sqrt(70.0), 1e-6 * (np.std(y, axis=0) + 1e-12))


def observable_states(model: VehicleModel, channels: tuple[str, ...]) -> NDArray[np.bool_]:
    """Per state, whether it lies in the observable subspace of the model linearised at its
    nominal point, measured through ``channels``."""
    A, _, _ = model.linearize()
    C = _output_matrix(model, channels)
    n = A.shape[0]
    blocks, M = [], C
    for _ in range(n):
        blocks.append(M)
        M = M @ A
    observability = np.vstack(blocks)
    scale = np.abs(observability).max(axis=1, keepdims=True) + 1e-300
    _, s, vt = np.linalg.svd(observability / scale)
    basis = vt[: int(np.sum(s > 1e-9 * s[0]))]
    return np.linalg.norm(basis, axis=0) > 0.99  # unit vector e_i inside the row space


def _output_matrix(model: VehicleModel, channels: tuple[str, ...]) -> FloatArray:
    """``d outputs / d x`` at the nominal state for the measured channels."""
    x0 = model.x0
    idx = [model.output_names.index(c) for c in channels]
    eps = 1e-6 * np.maximum(1.0, np.abs(x0))
    C = np.empty((len(idx), x0.size))
    for j in range(x0.size):
        step = np.zeros_like(x0)
        step[j] = eps[j]
        C[:, j] = (model.output(x0 + step)[idx] - model.output(x0 - step)[idx]) / (2 * eps[j])
    return C


def estimate(recording: Recording, model: VehicleModel, passes: int = 2) -> Residuals:
    """Smooth the record with the nominal model and compute the equation errors.

    The process noise of the second pass is the variance of the first pass's equation errors, so
    the smoother follows the data wherever the model is wrong.
    """
    channels = recording.measured_names
    y = recording.measurements.copy()
    for j, name in enumerate(channels):
        if name in ANGLES:
            y[:, j] = np.unwrap(y[:, j])
    u, dt = recording.inputs, recording.dt
    noise = white_noise_std(y)
    n = len(model.state_names)
    substeps = substeps_for(model, dt)
    measured = np.array([name in channels for name in model.state_names])
    Q = _initial_process_noise(model, y, u, channels, dt)
    Q = np.diag(np.where(measured, Q, Q * FOLLOW_MODEL))
    x0, P0 = _initial_state(model, y, channels, noise)
    for _ in range(passes):
        ekf = ExtendedKalmanFilter.from_model(model, dt, measured=channels, Q=Q,
                                              R=np.diag(noise**2), x0=x0, P0=P0,
                                              substeps=substeps)
        smoothed = ekf.smooth(u, y)
        x = smoothed.x[:, 0, :n]
        error = equation_error(model, x, u, dt, substeps)
        Q = np.diag(np.where(measured, np.maximum(np.var(error, axis=0), 1e-12 * (
            np.var(x, axis=0) + 1e-12)), np.diag(Q) / dt**2 * FOLLOW_MODEL) * dt**2)
    return Residuals(model, recording.time, dt, u, y, channels, x, smoothed.std[:, 0, :n],
                     error, noise, observable_states(model, channels), substeps,
                     Innovations.from_filter(ekf, smoothed.filtered, dt))


def _initial_state(model: VehicleModel, y: FloatArray, channels: tuple[str, ...],
                   noise: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The nominal state with measured states set to the first samples; a wide prior."""
    x0 = model.x0.copy()
    spread = np.ones_like(x0)
    for j, name in enumerate(channels):
        if name in model.state_names:
            i = model.state_names.index(name)
            x0[i] = y[0, j]
            spread[i] = 10 * noise[j] + 1e-6
    scale = np.maximum(np.abs(x0), 1.0)
    for i, name in enumerate(model.state_names):
        if name not in channels:
            spread[i] = scale[i]
    return x0, np.diag(spread**2)


def _initial_process_noise(model: VehicleModel, y: FloatArray, u: FloatArray,
                           channels: tuple[str, ...], dt: float) -> FloatArray:
    """A first guess of the per-step process noise variance of each state: a tenth of the
    spread of its derivative along a crude trajectory (measured states from the smoothed data,
    the others at their nominal values)."""
    window = min(len(y) // 2 * 2 - 1, 2 * int(1.0 / dt) + 1)
    smooth = signal.savgol_filter(y, max(window, 5), 3, axis=0) if len(y) > 5 else y
    crude = np.tile(model.x0, (len(y), 1))
    for j, name in enumerate(channels):
        if name in model.state_names:
            crude[:, model.state_names.index(name)] = smooth[:, j]
    rates = np.std(model.rhs(crude, u), axis=0)
    floor = 1e-6 * (np.abs(model.x0) + 1.0)
    return (np.maximum(0.1 * rates, floor) * dt) ** 2
