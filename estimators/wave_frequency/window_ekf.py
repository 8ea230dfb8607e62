"""The EKF of one window: the WF model with its peak frequencies appended to the state.

* **EKF.** The document's filter (docs/models.md 4.2 states ``[xi_1; xi_2]``,
  ``theta_dot = 0``) does not converge from the document's initial guess (0.4, 0.4, 0.55) in one
  300 s window: omega multiplies the unmeasured integral state xi_1. So each window runs two
  passes: an acquisition pass in the observable canonical realisation of the same transfer
  function (omega multiplies the measured output; converges from anywhere in the band in ~30 s
  but is biased high by 0.02-0.05 rad/s) and a refinement pass in the document's realisation
  from the acquisition's end (unbiased); ``acquisition=False`` runs the document's filter alone.
* **Process noise.** The DP wave-frequency patent's Q (0.5-0.8 per step on states whose variance
  is ~1) drowns the WF dynamics; Q is the WF model's own, with ``K_w = sqrt(4 lambda omega)
  sigma`` from the high-passed data's RMS sigma. omega is constant within a window
  (``parameter_noise = 0``); the state machine tracks changes from window to window.

The measured reasons are in the ``dp-wave-frequency`` reproduction.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from marine_envs.models.dp_vessel import wf_matrices

from ..base import as_batch
from ..ekf import ExtendedKalmanFilter
from ..kalman import held_noise_covariance
from .config import CHANNELS, PARAMETER_NAMES, SEED_Q, FloatArray, WaveFrequencyConfig

_OMEGA_LIMITS = (0.1, 3.0)  # rad/s: the EKF's omega is projected into this physical range

Realisation = Literal["document", "observable"]


def _wf_dynamics(realisation: Realisation, damping: float):
    """``(f, jacobian, H)`` of the three WF filters, state ``[s_1 (3), s_2 (3)]``.

    ``document``: docs/models.md 4.2, ``xi_1' = xi_2, xi_2' = -w^2 xi_1 - 2 lam w xi_2``, y = xi_2.
    ``observable``: the same transfer function ``s / (s^2 + 2 lam w s + w^2)`` with states
    ``z_1 = xi_2`` (measured) and ``z_2 = -w^2 xi_1``: ``z_1' = z_2 - 2 lam w z_1``,
    ``z_2' = -w^2 z_1``; omega multiplies the measured output.
    """
    i = np.arange(3)
    lam = damping

    if realisation == "document":
        def f(x: FloatArray, u: FloatArray, w: FloatArray) -> FloatArray:
            return np.concatenate([x[:, 3:], -w**2 * x[:, :3] - 2 * lam * w * x[:, 3:]], axis=1)

        def jacobian(x: FloatArray, u: FloatArray, w: FloatArray):
            A, Aw = np.zeros((x.shape[0], 6, 6)), np.zeros((x.shape[0], 6, 3))
            A[:, i, 3 + i], A[:, 3 + i, i], A[:, 3 + i, 3 + i] = 1.0, -w**2, -2 * lam * w
            Aw[:, 3 + i, i] = -2 * w * x[:, :3] - 2 * lam * x[:, 3:]
            return A, Aw

        return f, jacobian, np.hstack([np.zeros((3, 3)), np.eye(3)])

    def f_obs(x: FloatArray, u: FloatArray, w: FloatArray) -> FloatArray:
        return np.concatenate([x[:, 3:] - 2 * lam * w * x[:, :3], -w**2 * x[:, :3]], axis=1)

    def jacobian_obs(x: FloatArray, u: FloatArray, w: FloatArray):
        A, Aw = np.zeros((x.shape[0], 6, 6)), np.zeros((x.shape[0], 6, 3))
        A[:, i, i], A[:, i, 3 + i], A[:, 3 + i, i] = -2 * lam * w, 1.0, -w**2
        Aw[:, i, i], Aw[:, 3 + i, i] = -2 * lam * x[:, :3], -2 * w * x[:, :3]
        return A, Aw

    return f_obs, jacobian_obs, np.hstack([np.eye(3), np.zeros((3, 3))])


def _model_process_noise(omega: FloatArray, sigma: FloatArray, dt: float, damping: float,
                         realisation: Realisation) -> FloatArray:
    """Per-period covariance ``(6, 6)`` of the WF model's noise for peak ``omega`` (3,) and WF
    RMS ``sigma`` (3,), in the realisation's coordinates (mean over a batch is taken outside)."""
    K_w = np.sqrt(4 * damping * omega) * sigma
    A, E, _ = wf_matrices(omega, damping, K_w)
    Q = held_noise_covariance(A, E, dt, np.eye(3) / dt)
    if realisation == "observable":  # z = T xi, T = [[0, I], [-Omega^2, 0]]
        T = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.diag(omega**2), np.zeros((3, 3))]])
        Q = T @ Q @ T.T
    floor = 1e-9 * np.repeat(np.maximum(sigma, 1e-12) ** 2 * dt, 2)
    return (Q + Q.T) / 2 + np.diag(floor)


def wave_frequency_ekf(dt: float, omega0: ArrayLike, sigma: ArrayLike,
                       config: WaveFrequencyConfig | None = None,
                       realisation: Realisation = "document",
                       omega_variance: ArrayLike | None = None) -> ExtendedKalmanFilter:
    """The DP wave-frequency patent's EKF on ``[xi_1 (3), xi_2 (3), omega_x, omega_y,
    omega_psi]`` for a batch of windows (one filter per row of ``omega0``).

    :param dt: sample period, s.
    :param omega0: initial peak frequencies ``(3,)`` or ``(N, 3)``, rad/s.
    :param sigma: RMS of the high-passed WF motion ``(3,)`` or ``(N, 3)`` (m, m, rad); scales the
        model's process noise.
    :param config: settings (R, P0, damping, process noise).
    :param realisation: ``"document"`` (docs/models.md 4.2) or ``"observable"`` (see
        :func:`_wf_dynamics`); the states' P0 is the config's either way.
    :param omega_variance: P0 of omega ``(3,)``, (rad/s)^2; default the config's.
    """
    config = config or WaveFrequencyConfig()
    omega0 = np.atleast_2d(np.asarray(omega0, dtype=float))
    N = omega0.shape[0]
    sigma = as_batch("sigma", sigma, N, 3)
    f, jacobian, H = _wf_dynamics(realisation, config.damping)
    P0 = np.array(config.P0)
    if omega_variance is not None:
        P0[6:] = omega_variance
    if config.process_noise == "seed":
        Q, parameter_noise = np.diag(SEED_Q[:6]), np.sqrt(np.array(SEED_Q[6:]) / 0.5)
    else:
        Q = np.mean([_model_process_noise(o, s, dt, config.damping, realisation)
                     for o, s in zip(omega0, sigma, strict=True)], axis=0)
        parameter_noise = np.zeros(3)
    names = [f"{s}_{c}" for s in ("s1", "s2") for c in CHANNELS]
    ekf = ExtendedKalmanFilter(f, H, dt=dt, Q=Q, R=np.array(config.R), n_inputs=0,
                               state_names=names, measurement_names=CHANNELS,
                               parameter_names=PARAMETER_NAMES, parameter_noise=parameter_noise,
                               jacobian=jacobian, P0=np.diag(P0), batch_size=N,
                               divergence_ratio=1e6)  # the acquisition's start is wild, not bad
    ekf.reset(x0=np.concatenate([np.zeros((N, 6)), omega0], axis=1))
    return ekf


def run_ekf(ekf: ExtendedKalmanFilter, y_wf: FloatArray) -> FloatArray:
    """Filter ``y_wf`` ``(T, N, 3)`` from the EKF's current state; omega is projected into
    (0.1, 3) rad/s after each update (a negative or huge frequency is not a WF model and its
    negative damping would blow the filter up). Returns omega after each update ``(T, N, 3)``."""
    T, N = y_wf.shape[:2]
    history = np.empty((T, N, 3))
    u = np.zeros((N, 0))
    for k in range(T):
        ekf.update(y_wf[k])
        ekf.x[:, 6:] = np.clip(ekf.x[:, 6:], *_OMEGA_LIMITS)
        history[k] = ekf.x[:, 6:]
        if k < T - 1:
            ekf.predict(u)
    return history
