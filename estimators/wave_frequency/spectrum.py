"""The spectral pre-estimate theta0: a Whittle fit of the WF model's spectrum to each channel's
periodogram in the WF band, and the fitted peak's height over the noise floor."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from .config import WF_BAND, FloatArray

_FIT_ITERATIONS = 6  # fixed-point iterations of the profiled amplitude


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
    """The DP wave-frequency patent's dominant-frequency pre-estimate: FFT of each channel, a
    fit of the WF model's spectrum in ``band``, and its peak.

    The periodogram (Hann window, linear detrend) is fitted in ``band`` by the Whittle
    likelihood with the resonance of docs/models.md 4.2 (damping ``damping``) over a noise floor
    taken from the spectrum above ``2 band[1]`` (or the band's lowest decile when the Nyquist
    frequency is lower). A fit is more accurate than picking the largest bin: the periodogram of
    a 300 s record has 0.02 rad/s bins, each a chi-square variable with 2 degrees of freedom.

    :param y: records ``(T, ...)`` sampled every ``dt`` s (any unit).
    :param dt: sample period, s.
    :param band: the searched band, rad/s.
    :param damping: the WF model's relative damping, -.
    """
    import scipy.signal  # (here: `import estimators` need not load it)

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
