"""Wave-frequency (WF) model estimation for the DP vessel and the wave filter it retunes (seed 003).

Seed 003's pipeline, per window of measured ``[north, east, psi]`` (m, m, rad; MODELS.md 4.2)::

    model-update flag set -> window (600 s; 300 s in the example), Ts from the data (0.5 s)
      -> spectrum fit in the WF band 0.3-1.6 rad/s            -> pre-estimate theta0 (rad/s)
      -> 10th-order Butterworth high-pass at 0.35 rad/s        -> WF motion y_wf
      -> EKF on [xi (6); omega_x, omega_y, omega_psi]          -> omega_hat (rad/s)
      -> accept if |omega_hat - theta0| < 0.2 rad/s per DOF    -> hand omega_hat to the wave
         filter and clear the flag; else discard and repeat on the next window.

:class:`WaveFrequencyEstimator` runs this online as a state machine (flag ``model_update``) and,
once a window is accepted, keeps monitoring the spectrum: when its peak leaves the accepted
frequencies by more than the acceptance tolerance on two checks in a row (a sea-state change),
it sets the flag again. :class:`WaveFilter` is the DP observer whose WF model is updated: a
Kalman filter on :class:`~marine_envs.models.dp_vessel.DPVesselModel` that separates the
low-frequency (LF) motion from the WF motion, with per-row peak frequencies that can be changed
without losing its state. :class:`AdaptiveWaveFilter` joins the two as one
:class:`~estimators.base.Estimator`; :class:`WaveFrequencyWrapper` puts it on ``DPVessel-v0``.

Decisions (the measured reasons are in the ``dp-wave-frequency`` reproduction):

* **Units.** SI and radians everywhere. The seed's R = diag(1e-3, 1e-3, 2e-2) and P0 are read with
  psi in **degrees** (2e-2 deg^2 is a 0.14 deg gyrocompass, next to 0.032 m position noise; in rad
  it would be 8 deg of noise on 2 deg of WF yaw and the yaw estimate fails); they are converted
  once (:data:`SEED_R`, :data:`SEED_P0`).
* **Filter.** ``scipy.signal.sosfiltfilt`` (zero phase, 20th-order magnitude) after a linear
  detrend, padded by reflection (``padtype="even"``). A window is processed offline, so nothing
  forces a causal filter; ``sosfilt``'s start transient and phase cost accuracy, and odd padding
  adds a level step at each end that the filter rings on. ``zero_phase=False`` gives ``sosfilt``.
* **EKF.** The document's filter (MODELS.md 4.2 states ``[xi_1; xi_2]``, ``theta_dot = 0``) does
  not converge from the document's initial guess (0.4, 0.4, 0.55) in one 300 s window: omega
  multiplies the unmeasured integral state xi_1. So each window runs two passes: an acquisition
  pass in the observable canonical realisation of the same transfer function (omega multiplies
  the measured output; converges from anywhere in the band in ~30 s but is biased high by
  0.02-0.05 rad/s) and a refinement pass in the document's realisation from the acquisition's
  end (unbiased); ``acquisition=False`` runs the document's filter alone.
* **Process noise.** The seed's Q (0.5-0.8 per step on states whose variance is ~1) drowns the
  WF dynamics; Q is the WF model's own, with ``K_w = sqrt(4 lambda omega) sigma`` from the
  high-passed data's RMS sigma. omega is constant within a window (``parameter_noise = 0``);
  the state machine tracks changes from window to window.
* **High-pass bias.** The high-pass empties 0-0.35 rad/s, where the WF model still has power, so
  the EKF's omega is biased high by ~0.02 rad/s; the bias is predicted from the Whittle
  likelihood of the filtered model spectrum and subtracted (``highpass_correction=False`` skips).
* **Acceptance.** The seed's test, plus: theta0 must be an interior peak of the band whose
  fitted height is ``min_snr`` (30) times the noise floor (1 m of WF motion over 0.03 m of
  noise gives > 150; LF motion and noise alone at most ~10). Without it, a channel with no WF
  motion passes the seed's test one time in five (the EKF and the periodogram's largest bump
  land within 0.2 rad/s of each other by chance).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import gymnasium as gym
import numpy as np
import scipy.linalg
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from marine_envs.models.dp_vessel import DPVesselModel, DPVesselParams, wf_matrices

from .base import Estimator, as_batch, check_covariance
from .ekf import ExtendedKalmanFilter
from .kalman import KalmanFilter, _wrap, held_noise_covariance
from .wrappers import EstimatorWrapper

FloatArray = NDArray[np.float64]
DEG = math.pi / 180
#: The measured channels, in order (m, m, rad).
CHANNELS = ("north", "east", "psi")
#: Names of the estimated WF peak frequencies (rad/s), appended to the EKF's state.
PARAMETER_NAMES = ("omega_x", "omega_y", "omega_psi")
#: Seed 003's bands, rad/s: low-frequency motion and wave-frequency motion.
LF_BAND = (0.0, 0.25)
WF_BAND = (0.3, 1.6)
#: Seed 003's EKF measurement noise diag(1e-3 m^2, 1e-3 m^2, 2e-2 deg^2), in SI (rad^2).
SEED_R = (1e-3, 1e-3, 2e-2 * DEG**2)
#: Seed 003's P0 reordered to the EKF's state [xi_1 (3), xi_2 (3), omega (3)] and in SI: the seed's
#: order is [omega; xi_1; xi_2] with psi entries in deg (m^2 s^2, m^2, (rad/s)^2).
SEED_P0 = (1e5, 1e5, 1e7 * DEG**2, 1e5, 1e5, 1e7 * DEG**2, 1e3, 1e3, 1e6)
#: Seed 003's Q_ident per 0.5 s step, same order and units as :data:`SEED_P0`; used only with
#: ``process_noise="seed"`` (it makes the estimate wander; see the module docstring).
SEED_Q = (5e-1, 5e-1, 1e-1 * DEG**2, 8e-1, 8e-1, 1e-1 * DEG**2, 5e-3, 5e-3, 5e-2)
#: The document's initial guess of the peak frequencies, rad/s.
SEED_OMEGA_INITIAL = (0.4, 0.4, 0.55)
_OMEGA_LIMITS = (0.1, 3.0)  # rad/s: the EKF's omega is projected into this physical range
_MIN_WINDOW_PERIODS = 5  # a window must hold this many periods of the band's lowest frequency
_MAX_MISSING = 0.1  # fraction of missing samples an online window may interpolate over
_FIT_ITERATIONS = 6  # fixed-point iterations of the profiled amplitude
_BIAS_POINTS = 1000  # frequency points of the high-pass bias integral


# -- configuration -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class WaveFrequencyConfig:
    """Settings of the pipeline; units SI (s, rad/s, m, rad). Defaults are seed 003's.

    :param window: length of an estimation window, s (seed: 600; its example: 300).
    :param dt: expected sample period, s (seed: 0.5); data with a ``time`` column override it.
    :param band: the WF band searched for the spectral peak, rad/s.
    :param cutoff: high-pass cut-off, rad/s.
    :param order: Butterworth order of the high-pass.
    :param zero_phase: ``sosfiltfilt`` (True) or causal ``sosfilt`` (False).
    :param damping: relative damping lambda (zeta) of the WF model, -.
    :param omega_initial: the EKF's initial peak frequencies (x, y, psi), rad/s.
    :param R: EKF measurement-noise variances (m^2, m^2, rad^2).
    :param P0: EKF initial variances, state order [xi_1 (3), xi_2 (3), omega (3)].
    :param process_noise: ``"model"`` (the WF model's own, scaled to the data) or ``"seed"``
        (:data:`SEED_Q` literally, omega included).
    :param acquisition: run the acquisition pass before the document's EKF.
    :param refine_omega_std: prior std of omega in the refinement pass, rad/s.
    :param highpass_correction: subtract the high-pass bias of omega.
    :param tolerance: acceptance test ``|omega_hat - theta0| < tolerance``, rad/s (seed: 0.2).
    :param min_snr: a WF peak must stand this many times above the noise floor, -.
    :param monitor_window: data used by each sea-state check, s.
    :param monitor_every: period of the sea-state checks, s.
    :param change_threshold: a check fires when the spectral peak is this far from the accepted
        frequencies (any DOF), rad/s (default: the acceptance tolerance).
    :param change_confirmations: consecutive firing checks that set the model-update flag.
    """

    window: float = 600.0
    dt: float = 0.5
    band: tuple[float, float] = WF_BAND
    cutoff: float = 0.35
    order: int = 10
    zero_phase: bool = True
    damping: float = 0.1
    omega_initial: tuple[float, float, float] = SEED_OMEGA_INITIAL
    R: tuple[float, float, float] = SEED_R
    P0: tuple[float, ...] = SEED_P0
    process_noise: Literal["model", "seed"] = "model"
    acquisition: bool = True
    refine_omega_std: float = 0.1
    highpass_correction: bool = True
    tolerance: float = 0.2
    min_snr: float = 30.0
    monitor_window: float = 200.0
    monitor_every: float = 30.0
    change_threshold: float | None = None
    change_confirmations: int = 2

    def __post_init__(self) -> None:
        positive = ("window", "dt", "cutoff", "tolerance", "min_snr", "monitor_window",
                    "monitor_every", "refine_omega_std")
        for name in positive:
            _require_positive(name, getattr(self, name))
        lo, hi = _pair("band", self.band)
        object.__setattr__(self, "band", (lo, hi))
        if not 0 < self.damping < 1:
            raise ValueError(f"damping={self.damping!r} is invalid: must be in (0, 1)")
        if not (isinstance(self.order, int) and 1 <= self.order <= 20):
            raise ValueError(f"order={self.order!r} is invalid: an integer in [1, 20]")
        if self.process_noise not in ("model", "seed"):
            raise ValueError(f"process_noise={self.process_noise!r} is invalid: 'model' or 'seed'")
        for name, size in (("omega_initial", 3), ("R", 3), ("P0", 9)):
            vec = _vector(name, getattr(self, name), size)
            if not (vec > 0).all():
                raise ValueError(f"{name}={getattr(self, name)!r} is invalid: entries must be > 0")
            object.__setattr__(self, name, tuple(float(v) for v in vec))
        if self.change_threshold is not None:
            _require_positive("change_threshold", self.change_threshold)
        if not (isinstance(self.change_confirmations, int) and self.change_confirmations >= 1):
            raise ValueError(f"change_confirmations={self.change_confirmations!r} is invalid: "
                             "an integer >= 1")

    @property
    def threshold(self) -> float:
        """The sea-state change threshold in use, rad/s."""
        return self.tolerance if self.change_threshold is None else float(self.change_threshold)


def _require_positive(name: str, value: Any) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value!r} is invalid: must be a finite number > 0")


def _pair(name: str, value: Any) -> tuple[float, float]:
    vec = _vector(name, value, 2)
    if not 0 < vec[0] < vec[1]:
        raise ValueError(f"{name}={value!r} is invalid: need 0 < low < high (rad/s)")
    return float(vec[0]), float(vec[1])


def _vector(name: str, value: Any, size: int) -> FloatArray:
    try:
        vec = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be {size} numbers") from None
    if vec.size != size or not np.isfinite(vec).all():
        raise ValueError(f"{name}={value!r} is invalid: must be {size} finite numbers")
    return vec


# -- input checks ------------------------------------------------------------------------------
def sample_period(time: ArrayLike | None, dt: float | None = None, default: float = 0.5) -> float:
    """The sample period of a record, s: from its ``time`` column (s, uniform) if given, else
    ``dt``, else ``default``.

    :raises ValueError: non-uniform or non-increasing time, or ``dt`` disagreeing with it.
    """
    if time is None:
        value = default if dt is None else dt
        _require_positive("dt", value)
        return float(value)
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2 or not np.isfinite(t).all():
        raise ValueError("time must hold at least 2 finite values (s)")
    steps = np.diff(t)
    Ts = float(np.median(steps))
    bad = np.flatnonzero(np.abs(steps - Ts) > 1e-3 * Ts)
    if Ts <= 0 or bad.size:
        k = int(bad[0]) if bad.size else 0
        raise ValueError(f"time is not uniformly sampled: step {k} is {steps[k]:.6g} s, the "
                         f"median step {Ts:.6g} s (Ts must be constant; resample first)")
    if dt is not None and not math.isclose(dt, Ts, rel_tol=1e-3):
        raise ValueError(f"dt={dt!r} s disagrees with the time column's step {Ts:.6g} s")
    return Ts


def _check_window(y: ArrayLike, dt: float, config: WaveFrequencyConfig) -> FloatArray:
    """``y`` as ``(T, N, 3)`` after the boundary checks (shape, finiteness, length, Nyquist)."""
    a = np.asarray(y, dtype=float)
    if a.ndim == 2:
        a = a[:, None, :]
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"y has shape {np.shape(y)}; expected (T, 3) or (T, N, 3): "
                         f"{', '.join(CHANNELS)} (m, m, rad)")
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        k, _, c = bad[0]
        raise ValueError(f"y contains NaN or inf ({bad.shape[0]} values; first at sample {k}, "
                         f"channel {CHANNELS[c]!r}): fill or drop the gaps first")
    nyquist = math.pi / dt
    if nyquist <= config.band[1]:
        raise ValueError(f"dt={dt} s is too long: its Nyquist frequency {nyquist:.3g} rad/s "
                         f"does not reach the WF band's top {config.band[1]} rad/s")
    needed = _MIN_WINDOW_PERIODS * 2 * math.pi / config.band[0]
    if a.shape[0] * dt < needed:
        raise ValueError(f"window of {a.shape[0] * dt:g} s is too short: it must hold at least "
                         f"{_MIN_WINDOW_PERIODS} periods of {config.band[0]} rad/s "
                         f"({needed:.0f} s)")
    return a


# -- spectral pre-estimate ---------------------------------------------------------------------
@dataclasses.dataclass
class SpectralPeak:
    """Peak frequencies from a fit of the WF model's spectrum (shapes for ``k`` channels).

    :param theta0: fitted peak frequency, rad/s ``(..., k)``; NaN when the fit found no peak
        inside the band.
    :param snr: fitted peak height over the noise floor, - (NaN without a peak).
    :param frequencies: periodogram frequencies, rad/s ``(F,)``.
    :param psd: one-sided periodogram, unit^2 s/rad ``(F, ..., k)``.
    :param fit: the fitted model spectrum (WF resonance + floor) on ``frequencies``.
    """

    theta0: FloatArray
    snr: FloatArray
    frequencies: FloatArray
    psd: FloatArray
    fit: FloatArray


def _resonance(w: FloatArray, omega: FloatArray, damping: float) -> FloatArray:
    """``w^2 / ((omega^2 - w^2)^2 + (2 lambda omega w)^2)``: the WF model's |h|^2 / K_w^2."""
    return w**2 / ((omega**2 - w**2) ** 2 + (2 * damping * omega * w) ** 2)


def _whittle_fit(w: FloatArray, power: FloatArray, floor: FloatArray, grid: FloatArray,
                 damping: float) -> tuple[FloatArray, FloatArray]:
    """Whittle fit of ``K2 g(w; omega) / pi + floor`` to spectra ``power`` ``(F, M)`` over a
    grid of omega ``(G,)`` or one grid per spectrum ``(M, G)`` (uniform steps); K2 profiled out.
    Returns ``(omega (M,), K2 (M,))``, omega refined by a parabola through the best grid point
    and its neighbours (NaN if the best is at an end)."""
    grid = np.broadcast_to(grid, (power.shape[1], np.shape(grid)[-1]))
    g = _resonance(w[:, None, None], grid[None], damping) / math.pi  # (F, M, G)
    P, N0 = power[:, :, None], floor[None, :, None]
    K2 = np.maximum(np.mean((P - N0) / g, axis=0), 1e-300)  # (M, G)
    for _ in range(_FIT_ITERATIONS):  # fixed point of dJ/dK2 = 0: sum g (I - S) / S^2 = 0
        S = K2[None] * g + N0
        K2 = np.maximum(K2 * np.sum(P * g / S**2, axis=0) / np.sum(g / S, axis=0), 1e-300)
    S = K2[None] * g + N0
    J = np.sum(np.log(S) + P / S, axis=0)  # (M, G)
    rows, size = np.arange(J.shape[0]), grid.shape[1]
    best = np.argmin(J, axis=1)
    b = np.clip(best, 1, size - 2)
    a_, c_, m_ = J[rows, b - 1], J[rows, b + 1], J[rows, b]
    curvature = a_ - 2 * m_ + c_
    shift = np.where(curvature > 0, 0.5 * (a_ - c_) / np.where(curvature > 0, curvature, 1), 0)
    step = grid[:, 1] - grid[:, 0]
    inner = (best > 0) & (best < size - 1)
    omega = np.where(inner, grid[rows, b] + np.clip(shift, -1, 1) * step, np.nan)
    return omega, K2[rows, best]


def spectral_peak(y: ArrayLike, dt: float, band: tuple[float, float] = WF_BAND,
                  damping: float = 0.1) -> SpectralPeak:
    """Seed 003's dominant-frequency pre-estimate: FFT of each channel, a fit of the WF model's
    spectrum in ``band``, and its peak.

    The periodogram (Hann window, linear detrend) is fitted in ``band`` by the Whittle
    likelihood with the resonance of MODELS.md 4.2 (damping ``damping``) over a noise floor taken
    from the spectrum above ``2 band[1]`` (or the band's lowest decile when the Nyquist frequency
    is lower). A fit is more accurate than picking the largest bin: the periodogram of a 300 s
    record has 0.02 rad/s bins, each a chi-square variable with 2 degrees of freedom.

    :param y: records ``(T, ...)`` sampled every ``dt`` s (any unit).
    :param dt: sample period, s.
    :param band: the searched band, rad/s.
    :param damping: the WF model's relative damping, -.
    """
    a = np.asarray(y, dtype=float)
    shape = a.shape[1:]
    a = a.reshape(a.shape[0], -1)
    w, psd = scipy.signal.periodogram(a, fs=2 * math.pi / dt, window="hann", detrend="linear",
                                      axis=0)
    inside = (w >= band[0]) & (w <= band[1])
    above = w > 2 * band[1]
    floor = np.median(psd[above], axis=0) if above.sum() >= 5 else \
        np.quantile(psd[inside], 0.1, axis=0)
    floor = np.maximum(floor, 1e-12 * psd[inside].max(axis=0) + 1e-300)
    grid = np.arange(band[0], band[1] + 1e-9, 0.005)
    theta0, K2 = _whittle_fit(w[inside], psd[inside], floor, grid, damping)
    safe = np.where(np.isfinite(theta0), theta0, grid[0])
    peak = K2 / (math.pi * (2 * damping * safe) ** 2)
    fit = K2[None] * _resonance(w[:, None], safe[None], damping) / math.pi + floor[None]
    snr = np.where(np.isfinite(theta0), peak / floor, np.nan)
    return SpectralPeak(theta0.reshape(shape), snr.reshape(shape), w,
                        psd.reshape(-1, *shape), fit.reshape(-1, *shape))


# -- high-pass ---------------------------------------------------------------------------------
def highpass_sos(dt: float, cutoff: float = 0.35, order: int = 10) -> FloatArray:
    """Seed 003's Butterworth high-pass as second-order sections for period ``dt`` (s):
    ``scipy.signal.butter(order, cutoff, "highpass", output="sos", fs=2 pi / dt)`` (cut-off in
    rad/s; the bilinear transform is pre-warped to it). Sections, because a 10th-order transfer
    function's coefficients lose the poles to rounding at this low a digital cut-off (0.056)."""
    _require_positive("dt", dt)
    _require_positive("cutoff", cutoff)
    if cutoff >= math.pi / dt:
        raise ValueError(f"cutoff={cutoff} rad/s is above the Nyquist frequency "
                         f"{math.pi / dt:.3g} rad/s of dt={dt} s")
    return scipy.signal.butter(order, cutoff, btype="highpass", output="sos",
                               fs=2 * math.pi / dt)


def highpass(y: ArrayLike, dt: float, cutoff: float = 0.35, order: int = 10,
             zero_phase: bool = True) -> FloatArray:
    """The WF motion of records ``y`` ``(T, ...)``: linear detrend, then the Butterworth
    high-pass along axis 0 (see :func:`highpass_sos`), forward-backward with reflected padding
    (``zero_phase``) or causal from the first sample's steady state."""
    a = scipy.signal.detrend(np.asarray(y, dtype=float), axis=0)
    sos = highpass_sos(dt, cutoff, order)
    if zero_phase:
        return scipy.signal.sosfiltfilt(sos, a, axis=0, padtype="even",
                                        padlen=min(a.shape[0] - 1, 400))
    zi = scipy.signal.sosfilt_zi(sos).reshape(sos.shape[0], 2, *([1] * (a.ndim - 1)))
    return scipy.signal.sosfilt(sos, a, axis=0, zi=zi * a[0])[0]


def _highpass_power(w: FloatArray, dt: float, config: WaveFrequencyConfig) -> FloatArray:
    _, h = scipy.signal.sosfreqz(highpass_sos(dt, config.cutoff, config.order), worN=w,
                                 fs=2 * math.pi / dt)
    return np.abs(h) ** (4 if config.zero_phase else 2)


def highpass_bias(omega: ArrayLike, variance: ArrayLike, noise: ArrayLike, dt: float,
                  config: WaveFrequencyConfig | None = None) -> FloatArray:
    """The high-pass's bias of a likelihood estimate of omega, rad/s (same shape as ``omega``).

    The pseudo-true value that a Whittle (asymptotic Gaussian) likelihood of the unfiltered WF
    model reaches on data whose spectrum is the model's times the high-pass's power response
    plus white noise, minus omega. ``omega`` is the peak frequency (rad/s), ``variance`` the WF
    motion's variance and ``noise`` the measurement-noise variance, per channel.
    """
    config = config or WaveFrequencyConfig()
    om, var, r = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in
                                       (omega, variance, noise)))
    out = np.full(om.shape, np.nan)
    ok = np.isfinite(om) & (om > 0) & (var > 0)
    if not ok.any():
        return out
    w = np.linspace(1e-3, math.pi / dt, _BIAS_POINTS)
    H = _highpass_power(w, dt, config)
    lam = config.damping
    o, v, rr = om[ok], var[ok], r[ok]
    floor = rr * dt / math.pi  # one-sided density of white noise of variance r
    K2 = 4 * lam * o * v  # makes the resonance's variance v
    data = H[:, None] * K2[None] * _resonance(w[:, None], o[None], lam) / math.pi + floor[None]
    grids = o[:, None] + np.arange(-0.1, 0.1 + 1e-9, 0.004)[None]  # the bias is a few 0.01
    fitted = np.concatenate([_whittle_fit(w, data[:, j:j + 16], floor[j:j + 16],
                                          grids[j:j + 16], lam)[0]
                             for j in range(0, o.size, 16)])  # chunks bound the memory
    out[ok] = fitted - o
    return out


# -- the EKF of a window -----------------------------------------------------------------------
Realisation = Literal["document", "observable"]


def _wf_dynamics(realisation: Realisation, damping: float):
    """``(f, jacobian, H)`` of the three WF filters, state ``[s_1 (3), s_2 (3)]``.

    ``document``: MODELS.md 4.2, ``xi_1' = xi_2, xi_2' = -w^2 xi_1 - 2 lam w xi_2``, y = xi_2.
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
    """Seed 003's EKF on ``[xi_1 (3), xi_2 (3), omega_x, omega_y, omega_psi]`` for a batch of
    windows (one filter per row of ``omega0``).

    :param dt: sample period, s.
    :param omega0: initial peak frequencies ``(3,)`` or ``(N, 3)``, rad/s.
    :param sigma: RMS of the high-passed WF motion ``(3,)`` or ``(N, 3)`` (m, m, rad); scales the
        model's process noise.
    :param config: settings (R, P0, damping, process noise).
    :param realisation: ``"document"`` (MODELS.md 4.2) or ``"observable"`` (see
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


# -- one window --------------------------------------------------------------------------------
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
    """Seed 003's estimation on one window of measurements (or a batch of windows).

    :param y: measured ``north, east, psi`` (m, m, rad) ``(T, 3)``, or ``(T, N, 3)`` for ``N``
        windows filtered together; psi may be wrapped (it is unwrapped).
    :param dt: sample period, s; default: from ``time``, else the config's.
    :param config: settings (default: seed 003's).
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
    """Per DOF: a WF peak was found and stands out, and the EKF agrees with it (seed 003)."""
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


# -- the online state machine ------------------------------------------------------------------
@dataclasses.dataclass
class WindowEvent:
    """One thing the state machine did, for logs and plots.

    :param row: the batch row.
    :param time: s since the row's reset (the end of the data used).
    :param kind: ``"accepted"``, ``"rejected"`` (window discarded) or ``"sea_change"``.
    :param omega: accepted frequencies, or the rejected estimate, or the spectral peak that
        fired the change detector, rad/s ``(3,)``.
    :param detail: the estimate (accepted/rejected windows) or the reason text.
    """

    row: int
    time: float
    kind: Literal["accepted", "rejected", "sea_change"]
    omega: FloatArray
    detail: WindowEstimate | str


class WaveFrequencyEstimator:
    """Seed 003's model-update loop, online, for a batch of ``N`` independent data streams.

    Per row, a flag ``model_update`` (True after :meth:`reset`):

    * flag set (*estimating*): collect a fresh window; when full, run :func:`estimate_window`;
      accepted -> store the frequencies in :attr:`omega`, clear the flag; rejected -> discard it
      and collect the next window;
    * flag clear (*monitoring*): every ``monitor_every`` s, fit the spectrum of the last
      ``monitor_window`` s; if its peak is more than ``threshold`` from :attr:`omega` in any DOF
      on ``change_confirmations`` checks in a row, the sea has changed: set the flag again.

    :param config: the pipeline's settings (its ``dt`` is the period of :meth:`push`).
    :param batch_size: number of streams ``N``.
    """

    def __init__(self, config: WaveFrequencyConfig | None = None, batch_size: int = 1) -> None:
        self.config = config or WaveFrequencyConfig()
        c = self.config
        self.window_samples = round(c.window / c.dt)
        self.monitor_samples = min(round(c.monitor_window / c.dt), self.window_samples)
        self.check_samples = max(1, round(c.monitor_every / c.dt))
        _check_window(np.zeros((self.window_samples, 3)), c.dt, c)  # rejects a too-short window
        self.events: list[WindowEvent] = []
        self.bind(batch_size)

    def bind(self, batch_size: int) -> None:
        """Allocate ``batch_size`` streams (all reset)."""
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        # a ring buffer of the last window of samples; every row is written at ``_head``
        self._buffer = np.full((batch_size, self.window_samples, 3), np.nan)
        self._head = 0
        self.samples = np.zeros(batch_size, dtype=np.int64)
        self.model_update = np.ones(batch_size, dtype=bool)
        self.omega = np.tile(np.array(self.config.omega_initial), (batch_size, 1))
        self.theta0 = np.full((batch_size, 3), np.nan)
        #: last window's verdict: 1 accepted, 0 rejected, -1 none yet
        self.last_accepted = np.full(batch_size, -1, dtype=np.int8)
        self.updated = np.zeros(batch_size, dtype=bool)
        self._filled = np.zeros(batch_size, dtype=np.int64)
        self._since_check = np.zeros(batch_size, dtype=np.int64)
        self._firing = np.zeros(batch_size, dtype=np.int64)

    @property
    def batch_size(self) -> int:
        return self.model_update.size

    @property
    def time(self) -> FloatArray:
        """Time since each row's reset, s."""
        return self.samples * self.config.dt

    def reset(self, idx: ArrayLike | None = None) -> None:
        """Restart rows ``idx`` (all if None): flag set, frequencies back to the initial guess."""
        rows = _rows(idx, self.batch_size)
        self._buffer[rows] = np.nan
        self.samples[rows], self._filled[rows], self._since_check[rows] = 0, 0, 0
        self._firing[rows] = 0
        self.model_update[rows] = True
        self.omega[rows] = self.config.omega_initial
        self.theta0[rows] = np.nan
        self.last_accepted[rows] = -1
        self.updated[rows] = False

    def push(self, y: ArrayLike, mask: ArrayLike | None = None) -> NDArray[np.bool_]:
        """Add one sample per row: measured ``north, east, psi`` ``(N, 3)`` (m, m, rad); masked
        or non-finite channels count as missing. Runs the windows and checks that are due.

        :return: ``(N,)`` rows whose :attr:`omega` was just updated (an accepted window).
        """
        N = self.batch_size
        y = np.array(as_batch("y", y, N, 3), dtype=float)
        if mask is not None:
            y[~as_batch("mask", mask, N, 3).astype(bool)] = np.nan
        y[~np.isfinite(y)] = np.nan
        self._buffer[:, self._head] = y
        self._head = (self._head + 1) % self.window_samples
        self.samples += 1
        self._filled = np.minimum(self._filled + 1, self.window_samples)
        self._since_check += 1
        self.updated = np.zeros(N, dtype=bool)
        due = self.model_update & (self._filled >= self.window_samples)
        if due.any():
            self._estimate(np.flatnonzero(due))
        check = ~self.model_update & (self._since_check >= self.check_samples) & \
            (self._filled >= self.monitor_samples)
        if check.any():
            self._monitor(np.flatnonzero(check))
        return self.updated

    def _window(self, rows: NDArray[np.intp], samples: int) -> tuple[FloatArray, NDArray]:
        """The last ``samples`` of ``rows`` as ``(T, R, 3)`` with short gaps interpolated, and
        which rows had too many gaps to use."""
        order = (self._head - samples + np.arange(samples)) % self.window_samples
        data = self._buffer[rows[:, None], order[None]].transpose(1, 0, 2)
        unusable = np.zeros(rows.size, dtype=bool)
        t = np.arange(samples)
        for r in range(rows.size):
            for c in range(3):
                gap = ~np.isfinite(data[:, r, c])
                if gap.mean() > _MAX_MISSING:
                    unusable[r] = True
                elif gap.any():
                    data[gap, r, c] = np.interp(t[gap], t[~gap], data[~gap, r, c])
        return data, unusable

    def _estimate(self, rows: NDArray[np.intp]) -> None:
        data, unusable = self._window(rows, self.window_samples)
        self._filled[rows] = 0  # accepted or not, the next window starts afresh
        good = rows[~unusable]
        for r in rows[unusable]:
            self.last_accepted[r] = 0
            self.events.append(WindowEvent(int(r), float(self.time[r]), "rejected",
                                           np.full(3, np.nan), "too many missing samples"))
        if not good.size:
            return
        est = estimate_window(data[:, ~unusable], self.config.dt, self.config)
        for j, r in enumerate(good):
            ok = bool(est.accepted[j])
            self.last_accepted[r] = int(ok)
            self.theta0[r] = est.theta0[j]
            event = _row_estimate(est, j)
            kind: Literal["accepted", "rejected"] = "accepted" if ok else "rejected"
            self.events.append(WindowEvent(int(r), float(self.time[r]), kind,
                                           est.omega[j].copy(), event))
            if ok:
                self.omega[r] = est.omega[j]
                self.model_update[r], self.updated[r] = False, True
                self._filled[r] = self.window_samples  # the accepted window seeds the monitor
                self._since_check[r], self._firing[r] = 0, 0

    def _monitor(self, rows: NDArray[np.intp]) -> None:
        data, unusable = self._window(rows, self.monitor_samples)
        self._since_check[rows] = 0
        rows, data = rows[~unusable], data[:, ~unusable]
        if not rows.size:
            return
        data[:, :, 2] = np.unwrap(data[:, :, 2], axis=0)
        peak = spectral_peak(data, self.config.dt, self.config.band, self.config.damping)
        seen = np.isfinite(peak.theta0) & (np.nan_to_num(peak.snr) >= self.config.min_snr)
        moved = seen & (np.abs(np.where(seen, peak.theta0, 0) - self.omega[rows])
                        > self.config.threshold)
        fired = moved.any(axis=1)
        self._firing[rows] = np.where(fired, self._firing[rows] + 1, 0)
        changed = rows[self._firing[rows] >= self.config.change_confirmations]
        for r in changed:
            j = int(np.flatnonzero(rows == r)[0])
            self.events.append(WindowEvent(int(r), float(self.time[r]), "sea_change",
                                           peak.theta0[j].copy(),
                                           f"spectral peak {np.round(peak.theta0[j], 3)} "
                                           f"vs model {np.round(self.omega[r], 3)} rad/s"))
        self.model_update[changed] = True
        self._filled[changed], self._firing[changed] = 0, 0


def _rows(idx: ArrayLike | None, size: int) -> NDArray[np.intp]:
    rows = np.arange(size) if idx is None else np.atleast_1d(np.asarray(idx))
    return np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.intp)


def _row_estimate(e: WindowEstimate, j: int) -> WindowEstimate:
    """Row ``j`` of a batch estimate, as a single-window estimate."""
    peak = e.spectrum
    spectrum = SpectralPeak(peak.theta0[j], peak.snr[j], peak.frequencies, peak.psd[:, j],
                            peak.fit[:, j])
    return WindowEstimate(e.theta0[j], e.snr[j], e.omega[j], e.omega_ekf[j], e.omega_std[j],
                          e.history[:, j], e.acquisition[:, j], e.accepted[j],
                          e.dof_accepted[j], e.reasons[j:j + 1], e.y_wf[:, j], spectrum, e.dt)


# -- the DP observer (wave filter) -------------------------------------------------------------
class WaveFilter(Estimator):
    """The DP vessel's wave filter: a batch of Kalman filters on
    :class:`~marine_envs.models.dp_vessel.DPVesselModel` (15 states: LF position and heading,
    velocities, bias, WF states) measuring ``north, east, psi`` = LF + WF motion + noise. Each
    row has its own WF peak frequencies ``w0``; :meth:`set_wave_frequencies` changes them without
    touching the estimate or its covariance (the LF state is kept).

    The matrices for a ``w0`` are :meth:`KalmanFilter.from_model
    <estimators.kalman.KalmanFilter.from_model>`'s (the model linearised about ``x_ref, u_ref``,
    zero-order hold); the process noise is the model's own: unit-intensity white noise on its six
    disturbances, held over each period.

    :param dt: period of :meth:`predict`, s.
    :param w0: initial WF peak frequencies (north, east, psi), rad/s (default: seed 003's
        initial guess 0.4, 0.4, 0.55).
    :param params: the vessel's parameters (default :class:`DPVesselParams`); its ``w0`` is
        replaced per row.
    :param R: measurement-noise covariance ``(3, 3)`` or its diagonal (m^2, m^2, rad^2); default
        the DP environment's sensors (0.032 m, 0.032 m, 0.1 deg).
    :param x_ref, u_ref: linearisation point (default: the model's nominal point).
    :param x0, P0: default initial estimate ``(15,)`` and covariance of :meth:`reset`.
    :param batch_size: number of filters ``N``.
    :param divergence_ratio: as :class:`~estimators.kalman.KalmanFilter`.
    """

    measurement_names = CHANNELS

    def __init__(self, dt: float = 0.5, w0: ArrayLike = SEED_OMEGA_INITIAL, *,
                 params: DPVesselParams | None = None, R: ArrayLike | None = None,
                 x_ref: ArrayLike | None = None, u_ref: ArrayLike | None = None,
                 x0: ArrayLike | None = None, P0: ArrayLike | None = None,
                 batch_size: int = 1, divergence_ratio: float = 10.0) -> None:
        _require_positive("dt", dt)
        self.dt = float(dt)
        self.model = DPVesselModel(params)
        self.state_names = self.model.state_names
        n = len(self.state_names)
        self.R = check_covariance("R", np.array([1e-3, 1e-3, (0.1 * DEG) ** 2])
                                  if R is None else R, 3)
        if np.linalg.eigvalsh(self.R).min() <= 0:
            raise ValueError("R must be positive definite: every measurement has some noise")
        self.x_ref = self.model.x0 if x_ref is None else _vector("x_ref", x_ref, n)
        self.u_ref = self.model.u0 if u_ref is None else _vector("u_ref", u_ref, 3)
        self.x0 = self.x_ref.copy() if x0 is None else _vector("x0", x0, n)
        self.P0 = _default_P0(self.model) if P0 is None else check_covariance("P0", P0, n)
        if not divergence_ratio > 1:
            raise ValueError(f"divergence_ratio={divergence_ratio!r} is invalid: must be > 1")
        self.divergence_ratio = float(divergence_ratio)
        self.w0_initial = _frequencies("w0", w0)
        self._cache: dict[tuple[float, float, float], tuple[FloatArray, ...]] = {}
        self.H, self.d = self._matrices(self.w0_initial)[3:5]
        self.bind(batch_size)

    @classmethod
    def for_env(cls, env: Any, w0: ArrayLike = SEED_OMEGA_INITIAL, **kwargs: Any) -> WaveFilter:
        """A wave filter for a ``DPVessel-v0`` environment: its vessel parameters (except
        ``w0``), control period, linearisation point and sensor noise."""
        from .kalman import default_measurement_noise

        sim = env.unwrapped.sim
        if not isinstance(sim.model, DPVesselModel):
            raise ValueError(f"a wave filter needs the DP vessel; the env's model is "
                             f"{sim.model.name!r}")
        if tuple(sim.sensors.channels) != CHANNELS:
            raise ValueError(f"the env's sensors give {tuple(sim.sensors.channels)}; the wave "
                             f"filter needs {CHANNELS}")
        kwargs.setdefault("R", default_measurement_noise(sim))
        kwargs.setdefault("x_ref", sim.task.x_ref)
        kwargs.setdefault("u_ref", sim.task.u_ref)
        return cls(sim.dt, w0, params=sim.model.params, **kwargs)

    # -- per-w0 matrices ---------------------------------------------------------------------
    def _matrices(self, w0: FloatArray) -> tuple[FloatArray, ...]:
        """``(F, G, c, H, d, Q)`` for peak frequencies ``w0`` (cached)."""
        key = tuple(float(v) for v in w0)
        if key not in self._cache:
            model = self.model.with_params(w0=key)
            A, _, E = model.linearize(self.x_ref, self.u_ref)
            Q = held_noise_covariance(A, E, self.dt, np.eye(E.shape[1]) / self.dt)
            # a floor per state in its own unit (a floor from the trace would be ~1 m^2 per
            # step here: the bias's N^2 dwarf the positions' m^2)
            Q = Q + np.diag(1e-9 * np.diag(Q) + 1e-14)
            kf = KalmanFilter.from_model(model, self.dt, measured=CHANNELS, Q=Q, R=self.R,
                                         x_ref=self.x_ref, u_ref=self.u_ref)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = (kf.F, kf.G, kf.c, kf.H, kf.d, kf.Q)
        return self._cache[key]

    @property
    def wave_frequencies(self) -> FloatArray:
        """Each filter's WF peak frequencies ``(N, 3)``, rad/s."""
        return self._w0

    def set_wave_frequencies(self, w0: ArrayLike, idx: ArrayLike | None = None) -> None:
        """Use peak frequencies ``w0`` ``(3,)`` or ``(len(idx), 3)`` (rad/s) in filters ``idx``
        (all if None) from the next prediction on; estimates and covariances are kept."""
        rows = _rows(idx, self.batch_size)
        values = np.asarray(w0, dtype=float)
        values = np.broadcast_to(values, (rows.size, 3)) if values.shape == (3,) else values
        if values.shape != (rows.size, 3):
            raise ValueError(f"w0 has shape {np.shape(w0)}; expected (3,) or ({rows.size}, 3)")
        for r, w in zip(rows, values, strict=True):
            F, G, c, _, _, Q = self._matrices(_frequencies("w0", w))
            self._w0[r], self._F[r], self._G[r], self._c[r], self._Q[r] = w, F, G, c, Q

    # -- the estimator contract ----------------------------------------------------------
    def bind(self, batch_size: int) -> None:
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        F, G, c, _, _, Q = self._matrices(self.w0_initial)
        self._w0 = np.tile(self.w0_initial, (batch_size, 1))
        self._F, self._G = np.tile(F, (batch_size, 1, 1)), np.tile(G, (batch_size, 1, 1))
        self._c, self._Q = np.tile(c, (batch_size, 1)), np.tile(Q, (batch_size, 1, 1))
        self.x = np.tile(self.x0, (batch_size, 1))
        self.P = np.tile(self.P0, (batch_size, 1, 1))
        self.innovation = np.zeros((batch_size, 3))
        self.nis = np.zeros(batch_size)
        self._nis_mean = np.full(batch_size, 3.0)
        self.diverged = np.zeros(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        """Restart filters ``idx`` from ``x0, P0`` with the initial ``w0``."""
        rows = _rows(idx, self.batch_size)
        n = self.x.shape[1]
        x = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        if x.shape not in ((n,), (rows.size, n)) or not np.isfinite(x).all():
            raise ValueError(f"x0 must be {n} finite values or ({rows.size}, {n}); got shape "
                             f"{x.shape}")
        self.x[rows] = x
        self.P[rows] = self.P0 if P0 is None else check_covariance("P0", P0, n)
        self.set_wave_frequencies(self.w0_initial, rows)
        self.innovation[rows], self._nis_mean[rows], self.diverged[rows] = 0.0, 3.0, False

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        if dt is not None and not math.isclose(dt, self.dt):
            raise ValueError(f"dt={dt} differs from the filter's period {self.dt} s")
        u = as_batch("u", u, self.batch_size, 3)
        self.x = np.einsum("nij,nj->ni", self._F, self.x) + \
            np.einsum("nij,nj->ni", self._G, u) + self._c
        P = self._F @ self.P @ self._F.transpose(0, 2, 1) + self._Q
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        N = self.batch_size
        y = np.asarray(y, dtype=float)
        if y.shape != (N, 3):
            raise ValueError(f"y has shape {y.shape}; expected ({N}, 3): {', '.join(CHANNELS)}")
        valid = np.isfinite(y)
        if mask is not None:
            valid &= as_batch("mask", mask, N, 3).astype(bool)
        e = np.where(valid, y - (self.x @ self.H.T + self.d), 0.0)
        e[:, 2] = np.where(valid[:, 2], _wrap(e[:, 2]), 0.0)  # the compass wraps at +-pi
        # missing channels: zero rows of H and unit noise give them exactly zero gain
        H = self.H[None] * valid[:, :, None]
        both = valid[:, :, None] & valid[:, None, :]
        R = np.where(both, self.R, 0.0) + np.where(valid, 0.0, 1.0)[:, :, None] * np.eye(3)
        PHt = self.P @ H.transpose(0, 2, 1)
        S = H @ PHt + R
        sol = np.linalg.solve(S, np.concatenate([PHt.transpose(0, 2, 1), e[:, :, None]], axis=2))
        K, S_inv_e = sol[:, :, :-1].transpose(0, 2, 1), sol[:, :, -1]
        self.x = self.x + (K @ e[:, :, None])[:, :, 0]
        IKH = np.eye(self.x.shape[1]) - K @ H
        P = IKH @ self.P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        self.innovation, self.nis = e, np.einsum("ij,ij->i", e, S_inv_e)
        self._nis_mean = np.where(valid.any(axis=1), 0.95 * self._nis_mean + 0.05 * self.nis,
                                  self._nis_mean)
        finite = np.isfinite(self.x).all(axis=1) & np.isfinite(self.P).all(axis=(1, 2))
        self.diverged |= ~finite | (self._nis_mean > self.divergence_ratio * 3)
        return self.x, self.P

    @property
    def low_frequency(self) -> FloatArray:
        """The LF position and heading estimate ``(N, 3)`` (m, m, rad)."""
        return self.x[:, 0:3]

    @property
    def wave_motion(self) -> FloatArray:
        """The WF motion estimate ``(N, 3)`` (m, m, rad)."""
        return self.x[:, 12:15]


def _frequencies(name: str, value: ArrayLike) -> FloatArray:
    w = _vector(name, value, 3)
    if not (w > 0).all():
        raise ValueError(f"{name}={np.asarray(value).tolist()} is invalid: peak frequencies "
                         "must be > 0 rad/s")
    return w


def _default_P0(model: DPVesselModel) -> FloatArray:
    """Initial covariance: 5 m, 5 m, 5 deg of LF position, 0.5 m/s, 0.5 m/s, 1 deg/s, the bias's
    and the WF states' stationary spread."""
    p = model.params
    wave = scipy.linalg.solve_continuous_lyapunov(p.A_w, -p.E_w @ p.E_w.T)
    P0 = np.zeros((15, 15))
    P0[:6, :6] = np.diag([25.0, 25.0, (5 * DEG) ** 2, 0.25, 0.25, DEG**2])
    P0[6:9, 6:9] = np.diag(np.array(p.sigma_b) ** 2)
    P0[9:, 9:] = wave
    return (P0 + P0.T) / 2


# -- estimator + state machine, and the Gymnasium wrapper -----------------------------------
class AdaptiveWaveFilter(Estimator):
    """:class:`WaveFilter` whose WF model follows :class:`WaveFrequencyEstimator`: every
    measurement also feeds the state machine, and an accepted window's frequencies go to the
    filter (seed 003's "model update"). Works in :class:`~estimators.wrappers.EstimatorWrapper`
    and :class:`~estimators.wrappers.VectorEstimatorWrapper`.

    :param wave_filter: the DP observer (its initial ``w0`` should be the config's
        ``omega_initial``).
    :param estimator: the state machine (default: seed 003's settings with the filter's ``dt``).
    """

    measurement_names = CHANNELS

    def __init__(self, wave_filter: WaveFilter, estimator: WaveFrequencyEstimator | None = None
                 ) -> None:
        self.wave_filter = wave_filter
        self.estimator = estimator or WaveFrequencyEstimator(
            WaveFrequencyConfig(dt=wave_filter.dt, omega_initial=tuple(wave_filter.w0_initial)))
        if not math.isclose(self.estimator.config.dt, wave_filter.dt):
            raise ValueError(f"the estimator's dt {self.estimator.config.dt} s differs from the "
                             f"wave filter's {wave_filter.dt} s")
        self.state_names, self.dt = wave_filter.state_names, wave_filter.dt
        self.bind(wave_filter.batch_size)

    @classmethod
    def for_env(cls, env: Any, config: WaveFrequencyConfig | None = None,
                **kwargs: Any) -> AdaptiveWaveFilter:
        """For a ``DPVessel-v0`` environment; ``kwargs`` go to :meth:`WaveFilter.for_env`."""
        dt = env.unwrapped.sim.dt
        config = dataclasses.replace(config or WaveFrequencyConfig(), dt=dt)
        wave_filter = WaveFilter.for_env(env, w0=config.omega_initial, **kwargs)
        return cls(wave_filter, WaveFrequencyEstimator(config))

    # the filter's arrays are the estimate
    x = property(lambda self: self.wave_filter.x)
    P = property(lambda self: self.wave_filter.P)
    innovation = property(lambda self: self.wave_filter.innovation)
    diverged = property(lambda self: self.wave_filter.diverged)

    def bind(self, batch_size: int) -> None:
        self.wave_filter.bind(batch_size)
        self.estimator.bind(batch_size)
        self._fresh = np.ones(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        rows = _rows(idx, self.wave_filter.batch_size)
        self.wave_filter.reset(x0, P0, rows)
        self.estimator.reset(rows)
        self._fresh[rows] = True

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        self._fresh[:] = True
        return self.wave_filter.predict(u, dt)

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        out = self.wave_filter.update(y, mask)
        # a measurement repeated without a prediction (a restart after divergence) is one sample
        if self._fresh.all():
            updated = self.estimator.push(y, mask)
            rows = np.flatnonzero(updated)
            if rows.size:
                self.wave_filter.set_wave_frequencies(self.estimator.omega[rows], rows)
        self._fresh[:] = False
        return out


class WaveFrequencyWrapper(EstimatorWrapper):
    """``DPVessel-v0`` seen through the adaptive wave filter: the observation is the filter's
    15-state estimate (LF position and heading first, then velocities, bias and WF states; what
    :meth:`agents.lqr.LQRPolicy.for_env` reads with ``observed="auto"``), and the WF model is
    re-estimated online (seed 003).

    ``info`` gets, besides :class:`~estimators.wrappers.EstimatorWrapper`'s keys:

    * ``wave_frequencies`` ``(3,)``: the frequencies the filter uses now, rad/s;
    * ``wave_model_update``: the seed's flag (a window is being collected for estimation);
    * ``wave_window_accepted``: the last window's verdict (None before the first);
    * ``wave_frequencies_updated``: this step changed the filter's frequencies;
    * ``wave_theta0`` ``(3,)``: the last window's spectral pre-estimate, rad/s (None before the
      first; NaN where a window had no peak).

    :param env: a ``DPVessel-v0`` environment.
    :param config: the pipeline's settings (``dt`` is taken from the environment).
    :param kwargs: to :class:`~estimators.wrappers.EstimatorWrapper` (``x0``, ``P0``, ...).
    """

    def __init__(self, env: gym.Env, config: WaveFrequencyConfig | None = None,
                 **kwargs: Any) -> None:
        # recorded first, so that env.spec rebuilds this wrapper, not its base
        gym.utils.RecordConstructorArgs.__init__(self, config=config, **kwargs)
        self.adaptive = AdaptiveWaveFilter.for_env(env, config)
        super().__init__(env, self.adaptive, **kwargs)

    def _correct(self, obs: np.ndarray, info: dict[str, Any]):
        estimate, info = super()._correct(obs, info)
        machine = self.adaptive.estimator
        verdict = int(machine.last_accepted[0])
        info = {**info, "wave_frequencies": self.adaptive.wave_filter.wave_frequencies[0].copy(),
                "wave_model_update": bool(machine.model_update[0]),
                "wave_window_accepted": None if verdict < 0 else bool(verdict),
                "wave_frequencies_updated": bool(machine.updated[0]),
                "wave_theta0": None if verdict < 0 else machine.theta0[0].copy()}
        return estimate, info


__all__ = ["AdaptiveWaveFilter", "CHANNELS", "LF_BAND", "PARAMETER_NAMES", "SEED_OMEGA_INITIAL",
           "SEED_P0", "SEED_Q", "SEED_R", "SpectralPeak", "WF_BAND", "WaveFilter",
           "WaveFrequencyConfig", "WaveFrequencyEstimator", "WaveFrequencyWrapper",
           "WindowEstimate", "WindowEvent", "estimate_window", "highpass", "highpass_bias",
           "highpass_sos", "run_ekf", "sample_period", "spectral_peak", "wave_frequency_ekf"]
