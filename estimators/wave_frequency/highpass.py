"""The Butterworth high-pass that extracts the WF motion, and the bias it puts on omega.

* **Filter.** ``scipy.signal.sosfiltfilt`` (zero phase, 20th-order magnitude) after a linear
  detrend, padded by reflection (``padtype="even"``). A window is processed offline, so nothing
  forces a causal filter; ``sosfilt``'s start transient and phase cost accuracy, and odd padding
  adds a level step at each end that the filter rings on. ``zero_phase=False`` gives ``sosfilt``.
* **High-pass bias.** The high-pass empties 0-0.35 rad/s, where the WF model still has power, so
  the EKF's omega is biased high by ~0.02 rad/s; the bias is predicted from the Whittle
  likelihood of the filtered model spectrum and subtracted (``highpass_correction=False`` skips).

The measured reasons are in the ``dp-wave-frequency`` reproduction.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .config import FloatArray, WaveFrequencyConfig, _require_positive
from .spectrum import _resonance, _whittle_fit

_BIAS_POINTS = 1000  # frequency points of the high-pass bias integral


def highpass_sos(dt: float, cutoff: float = 0.35, order: int = 10) -> FloatArray:
    """The DP wave-frequency patent's Butterworth high-pass as second-order sections for
    period ``dt`` (s): ``scipy.signal.butter(order, cutoff, "highpass", output="sos",
    fs=2 pi / dt)`` (cut-off in rad/s; the bilinear transform is pre-warped to it). Sections,
    because a 10th-order transfer function's coefficients lose the poles to rounding at this low
    a digital cut-off (0.056)."""
    import scipy.signal  # (here: `import estimators` need not load it)

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
    import scipy.signal  # (here: `import estimators` need not load it)

    a = scipy.signal.detrend(np.asarray(y, dtype=float), axis=0)
    sos = highpass_sos(dt, cutoff, order)
    if zero_phase:
        return scipy.signal.sosfiltfilt(sos, a, axis=0, padtype="even",
                                        padlen=min(a.shape[0] - 1, 400))
    zi = scipy.signal.sosfilt_zi(sos).reshape(sos.shape[0], 2, *([1] * (a.ndim - 1)))
    return scipy.signal.sosfilt(sos, a, axis=0, zi=zi * a[0])[0]


def _highpass_power(w: FloatArray, dt: float, config: WaveFrequencyConfig) -> FloatArray:
    import scipy.signal  # (here: `import estimators` need not load it)

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
