"""One window: high-pass, spectral pre-estimate, the EKF's two passes, bias removal and the
acceptance test.

**Acceptance.** The DP wave-frequency patent's test, plus: theta0 must be an interior peak of the
band whose fitted height is ``min_snr`` (30) times the noise floor (1 m of WF motion over 0.03 m
of noise gives > 150; LF motion and noise alone at most ~10). Without it, a channel with no WF
motion passes the patent's test one time in five (the EKF and the periodogram's largest bump
land within 0.2 rad/s of each other by chance); the ``dp-wave-frequency`` reproduction measures
it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .config import CHANNELS, FloatArray, WaveFrequencyConfig, _check_window, sample_period
from .highpass import highpass, highpass_bias
from .spectrum import SpectralPeak, spectral_peak
from .window_ekf import run_ekf, wave_frequency_ekf


@dataclasses.dataclass
class WindowEstimate:
    """The outcome of :func:`estimate_window` (``N`` windows; without the batch axis when a
    single ``(T, 3)`` window was given). Frequencies in rad/s.

    :param theta0: spectral pre-estimate ``(N, 3)`` (NaN: no peak in the band).
    :param snr: fitted spectral peak over the noise floor ``(N, 3)``.
    :param omega: the EKF's estimate, high-pass bias removed ``(N, 3)``.
    :param omega_ekf: the EKF's estimate as filtered ``(N, 3)``.
    :param omega_std: its standard deviation ``(N, 3)``.
    :param history: the delivered estimate over the window ``(T, N, 3)`` (the last pass, bias
        removed).
    :param acquisition: the acquisition pass's estimate over the window ``(T, N, 3)`` (NaN if
        not run).
    :param accepted: all three DOF pass the acceptance test ``(N,)``.
    :param dof_accepted: per DOF ``(N, 3)``.
    :param reasons: why each window was rejected (empty when accepted).
    :param y_wf: the high-passed measurements ``(T, N, 3)``.
    :param spectrum: the spectral fit (periodogram and model) of the raw window.
    :param dt: the sample period used, s.
    """

    theta0: FloatArray
    snr: FloatArray
    omega: FloatArray
    omega_ekf: FloatArray
    omega_std: FloatArray
    history: FloatArray
    acquisition: FloatArray
    accepted: NDArray[np.bool_]
    dof_accepted: NDArray[np.bool_]
    reasons: list[str]
    y_wf: FloatArray
    spectrum: SpectralPeak
    dt: float


def estimate_window(y: ArrayLike, dt: float | None = None, config: WaveFrequencyConfig | None
                    = None, *, time: ArrayLike | None = None) -> WindowEstimate:
    """The DP wave-frequency patent's estimation on one window of measurements (or a batch of
    windows).

    :param y: measured ``north, east, psi`` (m, m, rad) ``(T, 3)``, or ``(T, N, 3)`` for ``N``
        windows filtered together; psi may be wrapped (it is unwrapped).
    :param dt: sample period, s; default: from ``time``, else the config's.
    :param config: settings (default: the patent's).
    :param time: the samples' times ``(T,)``, s (checked to be uniform).
    :raises ValueError: wrong shape, NaN or inf, a window shorter than 5 periods of the band's
        lowest frequency, a sample period that does not resolve the band, non-uniform time.
    """
    config = config or WaveFrequencyConfig()
    dt = sample_period(time, dt, config.dt)
    single = np.ndim(y) == 2
    if time is not None and np.shape(time)[0] != np.shape(y)[0]:
        raise ValueError(f"time has {np.shape(time)[0]} samples but y has {np.shape(y)[0]}")
    a = _check_window(y, dt, config).copy()
    a[:, :, 2] = np.unwrap(a[:, :, 2], axis=0)
    peak = spectral_peak(a, dt, config.band, config.damping)
    y_wf = highpass(a, dt, config.cutoff, config.order, config.zero_phase)
    sigma = np.maximum(np.sqrt(np.maximum(y_wf.var(axis=0) - np.array(config.R), 0)),
                       1e-6 * np.maximum(y_wf.std(axis=0), 1e-12))
    T, N = y_wf.shape[:2]
    start = np.tile(config.omega_initial, (N, 1))
    acquisition = np.full((T, N, 3), np.nan)
    omega_var = None
    if config.acquisition:
        ekf = wave_frequency_ekf(dt, start, sigma, config, "observable")
        acquisition = run_ekf(ekf, y_wf)
        start, omega_var = acquisition[-1], np.full(3, config.refine_omega_std**2)
    ekf = wave_frequency_ekf(dt, start, sigma, config, "document", omega_var)
    history = run_ekf(ekf, y_wf)
    omega_ekf, omega_std = history[-1], ekf.parameter_std.copy()
    bias = np.zeros((N, 3))
    if config.highpass_correction:
        bias = highpass_bias(omega_ekf, sigma**2, np.array(config.R), dt, config)
        bias = np.where(np.isfinite(bias), bias, 0.0)
    omega = omega_ekf - bias
    dof_ok, reasons = _acceptance(peak.theta0, peak.snr, omega, config)
    out = WindowEstimate(peak.theta0, peak.snr, omega, omega_ekf, omega_std, history - bias,
                         acquisition, dof_ok.all(axis=1), dof_ok, reasons, y_wf, peak, dt)
    return _row_estimate(out, 0) if single else out


def _acceptance(theta0: FloatArray, snr: FloatArray, omega: FloatArray,
                config: WaveFrequencyConfig) -> tuple[NDArray[np.bool_], list[str]]:
    """Per DOF: a WF peak was found and stands out, and the EKF agrees with it (the DP
    wave-frequency patent)."""
    lo, hi = config.band
    found = np.isfinite(theta0)
    strong = found & (np.nan_to_num(snr) >= config.min_snr)
    inside = np.isfinite(omega) & (omega >= lo) & (omega <= hi)
    close = strong & inside & (np.abs(omega - np.where(found, theta0, 0)) < config.tolerance)
    reasons = []
    for n in range(omega.shape[0]):
        why = []
        for c, name in enumerate(CHANNELS):
            if not found[n, c]:
                why.append(f"{name}: no spectral peak inside {lo}-{hi} rad/s")
            elif not strong[n, c]:
                why.append(f"{name}: spectral peak only {snr[n, c]:.3g} x the noise floor "
                           f"(< {config.min_snr:g}): no WF motion")
            elif not inside[n, c]:
                why.append(f"{name}: EKF estimate {omega[n, c]:.3f} rad/s outside the band")
            elif not close[n, c]:
                why.append(f"{name}: |omega - theta0| = {abs(omega[n, c] - theta0[n, c]):.3f}"
                           f" >= {config.tolerance} rad/s")
        reasons.append("; ".join(why))
    return close, reasons


def _row_estimate(e: WindowEstimate, j: int) -> WindowEstimate:
    """Row ``j`` of a batch estimate, as a single-window estimate."""
    peak = e.spectrum
    spectrum = SpectralPeak(peak.theta0[j], peak.snr[j], peak.frequencies, peak.psd[:, j],
                            peak.fit[:, j])
    return WindowEstimate(e.theta0[j], e.snr[j], e.omega[j], e.omega_ekf[j], e.omega_std[j],
                          e.history[:, j], e.acquisition[:, j], e.accepted[j],
                          e.dof_accepted[j], e.reasons[j:j + 1], e.y_wf[:, j], spectrum, e.dt)
