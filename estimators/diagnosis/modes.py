"""The record's own modes against the model's: a free decay read as a naval architect reads it.

A free decay (inputs held, released from an offset) oscillates at the vehicle's natural frequency
and decays at its damping. :func:`decay_analysis` reads both off the extrema of a measured channel
(period from the zero crossings, damping from the logarithmic decrement), and with them the
extinction curve (decrement against mean amplitude) that shows amplitude-dependent damping.
:func:`check_modes` compares the record's mode with the linearised model's observable modes, so a
model with the wrong natural frequency is named as such, with the parameter to set or calibrate,
and :func:`mode_start` finds the parameter values that put the model's mode where the record's is
(the start of an output-error calibration that would otherwise lock onto a wrong period).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from marine_envs.models import VehicleModel

FloatArray = NDArray[np.float64]
#: A model mode matches the record's when their natural frequencies differ by less than this.
MODE_TOLERANCE = 0.25
#: Extrema smaller than this many noise deviations are not read.
MIN_EXTREMUM_SNR = 5.0


@dataclass(frozen=True)
class Decay:
    """A free decay's extrema and what they say.

    :param times: times of the extrema, s.  :param amplitudes: their absolute values (units of
        the channel) about the tail's level ``offset``.
    :param omega_n: natural frequency, rad/s.  :param zeta: damping ratio, from the first
        ``cycles`` periods.  :param period: damped period, s.
    """

    times: FloatArray
    amplitudes: FloatArray
    offset: float
    omega_n: float
    zeta: float
    period: float

    def extinction(self) -> tuple[FloatArray, FloatArray]:
        """The extinction curve: mean amplitude of each period and its logarithmic decrement
        ``ln(a_k / a_{k+2})`` (the standard presentation of roll-decay tests)."""
        a = self.amplitudes
        return 0.5 * (a[:-2] + a[2:]), np.log(a[:-2] / a[2:])

    def periods(self) -> tuple[FloatArray, FloatArray]:
        """Period against mean amplitude, s (constant for a linear restoring moment)."""
        a, t = self.amplitudes, self.times
        return 0.5 * (a[:-2] + a[2:]), t[2:] - t[:-2]

    def to_dict(self) -> dict[str, float]:
        return {"omega_n": self.omega_n, "zeta": self.zeta, "period": self.period,
                "extrema": int(len(self.times))}


def decay_analysis(time: FloatArray, y: FloatArray, noise: float,
                   cycles: int = 3) -> Decay | None:
    """The decay of ``y`` about its tail level, or None when fewer than two periods rise above
    the noise (not a decay)."""
    offset = float(np.median(y[int(0.8 * len(y)):]))
    side = np.where(y >= offset, 1, -1)  # a sample exactly at the offset is on one side
    crossings = np.flatnonzero(side[1:] != side[:-1])
    z = y - offset
    edges = np.concatenate([[0], crossings + 1])  # the last half cycle is cut by the end
    times, values = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b - a < 3:
            continue
        k = a + int(np.argmax(np.abs(z[a:b])))
        if abs(z[k]) < MIN_EXTREMUM_SNR * noise:
            break
        if k == 0 and not _peaks_at_start(z):
            continue  # the record starts mid-swing: its first sample is no extremum
        t_peak, value = _refined_peak(time, z, k)
        times.append(t_peak)
        values.append(value + offset)
    offset = _level(np.array(values), offset)
    amplitudes = [abs(v - offset) for v in values]
    if len(times) < 5:
        return None
    t, amp = np.array(times), np.array(amplitudes)
    n = min(2 * cycles, len(t) - 1)
    period = 2 * float(np.mean(np.diff(t[: n + 1])))
    delta = 2 * float(np.log(amp[0] / amp[n])) / n  # per period
    zeta = delta / math.sqrt(4 * math.pi**2 + delta**2)
    omega_n = 2 * math.pi / period / math.sqrt(max(1 - zeta**2, 1e-12))
    return Decay(t, amp, offset, omega_n, zeta, period)


def _level(extrema: FloatArray, guess: float) -> float:
    """The level a decay settles to, from its extrema ``y_k``: for a geometric decay about ``c``
    each three give ``c = (y0 y2 - y1^2) / (y0 + y2 - 2 y1)`` exactly; the median over the
    record (the tail's median when too few)."""
    y0, y1, y2 = extrema[:-2], extrema[1:-1], extrema[2:]
    denominator = y0 + y2 - 2 * y1
    ok = np.abs(denominator) > 1e-12
    levels = (y0 * y2 - y1**2)[ok] / denominator[ok]
    return float(np.median(levels)) if levels.size >= 3 else guess


def _peaks_at_start(z: FloatArray) -> bool:
    """The parabola through the first three samples peaks within a sample of the first
    (a release from rest), not beyond it (a swing already under way)."""
    a, b, c = z[:3]
    curvature = a - 2 * b + c
    return curvature != 0 and -2.0 <= 0.5 * (a - c) / curvature <= -0.5


def _refined_peak(time: FloatArray, z: FloatArray, k: int) -> tuple[float, float]:
    """The extremum at sample ``k`` refined by a parabola through its neighbours (the first
    sample's through the next two)."""
    if k == 0 and len(z) > 2:
        a, b, c = z[:3]
        s = max(0.5 * (a - c) / (a - 2 * b + c), -2.0)
        return float(time[1] + s * (time[1] - time[0])), float(b - 0.25 * (a - c) * s)
    if 0 < k < len(z) - 1:
        a, b, c = z[k - 1], z[k], z[k + 1]
        curvature = a - 2 * b + c
        if curvature != 0:
            s = float(np.clip(0.5 * (a - c) / curvature, -0.5, 0.5))
            return float(time[k] + s * (time[k + 1] - time[k])), float(b - 0.25 * (a - c) * s)
    return float(time[k]), float(z[k])


# -- the model's modes ----------------------------------------------------------------------------
def model_modes(model: VehicleModel, channels: Sequence[str]) -> list[tuple[float, float]]:
    """``(omega_n, zeta)`` of every mode of the linearised model that the channels see
    (oscillatory pairs once), slowest first."""
    A, _, _ = model.linearize()
    index = [model.state_names.index(c) for c in channels if c in model.state_names]
    values, vectors = np.linalg.eig(A)
    modes = []
    for lam, v in zip(values, vectors.T, strict=True):
        if lam.imag < 0 or not index or np.max(np.abs(v[index])) < 1e-6 * np.max(np.abs(v)):
            continue
        omega = float(abs(lam))
        modes.append((omega, float(-lam.real / omega) if omega > 0 else 1.0))
    return sorted(modes)


def nearest_mode(model: VehicleModel, channels: Sequence[str],
                 omega: float) -> tuple[float, float] | None:
    """The model's observable oscillatory mode nearest ``omega`` (rad/s): a real pole (``zeta``
    1, or -1 when unstable) rings at no frequency."""
    oscillatory = [m for m in model_modes(model, channels) if abs(m[1]) < 1.0]
    return min(oscillatory, key=lambda m: abs(math.log(m[0] / omega)), default=None)


def check_modes(model: VehicleModel, channels: Sequence[str], decay: Decay,
                names: Sequence[str] = ()) -> dict[str, object]:
    """The record's mode against the model's: ``{"record", "model", "matches", "advice"}``;
    ``advice`` names the parameter that moves the nearest mode most when it does not match."""
    mode = nearest_mode(model, channels, decay.omega_n)
    matches = mode is not None and abs(mode[0] / decay.omega_n - 1) < MODE_TOLERANCE
    out: dict[str, object] = {
        "record": {"omega_n": round(decay.omega_n, 4), "zeta": round(decay.zeta, 5),
                   "period": round(decay.period, 4)},
        "model": [{"omega_n": round(w, 4), "zeta": round(z, 5)}
                  for w, z in model_modes(model, channels)],
        "matches": bool(matches), "advice": ""}
    if not matches:
        lever = _frequency_lever(model, channels, decay.omega_n, names)
        near = f"{mode[0]:.3g} rad/s" if mode else "no oscillatory mode"
        out["advice"] = (
            f"the record oscillates at {decay.omega_n:.3g} rad/s (period {decay.period:.3g} s), "
            f"the model at {near}: it is not this vehicle's model as set"
            + (f"; set or calibrate {lever}" if lever else ""))
    return out


def _frequency_lever(model: VehicleModel, channels: Sequence[str], omega: float,
                     names: Sequence[str]) -> str:
    """The parameter (of ``names``, or of all numeric ones) whose relative change moves the
    mode nearest ``omega`` most."""
    base = nearest_mode(model, channels, omega)
    if base is None:
        return ""
    candidates = names or [k for k, v in vars(model.params).items()
                           if isinstance(v, float) and v != 0]
    best, lever = 0.0, ""
    for name in candidates:
        value = float(getattr(model.params, name))
        try:
            moved = nearest_mode(model.with_params(**{name: value * 1.01}), channels, omega)
        except ValueError:
            continue
        sensitivity = abs(math.log(moved[0] / base[0])) if moved else 0.0
        if sensitivity > best * 1.5:
            best, lever = sensitivity, name
    return lever


def mode_start(model: VehicleModel, channels: Sequence[str], decay: Decay,
               names: Sequence[str]) -> dict[str, float] | None:
    """Values of ``names`` that put the model's observable mode at the record's natural
    frequency and damping ratio, or None when they cannot (no oscillatory mode, or the names do
    not move it)."""
    start = {n: float(getattr(model.params, n)) for n in names}
    if nearest_mode(model, channels, decay.omega_n) is None or not names:
        return None
    target = np.array([math.log(decay.omega_n), decay.zeta])

    def mismatch(values: FloatArray) -> FloatArray:
        try:
            trial = model.with_params(**dict(zip(names, values.tolist(), strict=True)))
        except ValueError:
            return np.full(2, 1e3)
        mode = nearest_mode(trial, channels, decay.omega_n)
        if mode is None:
            return np.full(2, 1e3)
        return np.array([math.log(mode[0]), mode[1]]) - target

    x0 = np.array(list(start.values()))
    fit = optimize.least_squares(mismatch, x0, x_scale=np.maximum(np.abs(x0), 1e-3),
                                 method="lm" if len(names) <= 2 else "trf")
    if abs(fit.fun[0]) > 1e-3:  # the frequency must match; the damping where the names reach
        return None
    return dict(zip(names, fit.x.tolist(), strict=True))


def free_decays(time: FloatArray, u: FloatArray, y: FloatArray, noise: FloatArray,
                channels: Sequence[str]) -> dict[str, Decay]:
    """The decay of each channel of a record with held inputs (none when the inputs move)."""
    if u.size and np.any(np.ptp(u, axis=0) > 0):
        return {}
    decays = {}
    for j, channel in enumerate(channels):
        decay = decay_analysis(time, y[:, j], float(noise[j]))
        if decay is not None:
            decays[channel] = decay
    return decays
