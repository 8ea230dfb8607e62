"""Plain reference fits that do not use the diagnosis: a linear decay fitted by least squares,
Nomoto and Nomoto-Norrbin fitted in free simulation (own RK4 code), leave one zigzag out."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import optimize

from marine_envs.recording import Recording

ZIGZAG_DECIMATION = 5  # 20 Hz -> 4 Hz for the reference fits


def linear_decay_fit(time_: np.ndarray, x: np.ndarray) -> dict[str, float]:
    """Least squares of ``x = A exp(-zeta wn t) cos(wd t + phase) + offset`` (wd = wn
    sqrt(1 - zeta^2)) over the whole record: wn, zeta, their std, the RMS residual."""
    def model(t, a, wn, zeta, phase, offset):
        wd = wn * math.sqrt(max(1 - zeta**2, 1e-12))
        return a * np.exp(-zeta * wn * t) * np.cos(wd * t + phase) + offset

    centred = x - np.mean(x)
    cross = time_[np.flatnonzero(np.diff(np.signbit(centred)))]
    wd0 = math.pi * (len(cross) - 1) / (cross[-1] - cross[0])
    quarter = max(len(x) // 4, 1)
    ratio = np.std(centred[:quarter]) / max(np.std(centred[-quarter:]), 1e-300)
    zeta0 = min(max(math.log(max(ratio, 1.0001)) / (wd0 * 0.75 * (time_[-1] - time_[0])), 1e-4),
                0.5)
    a0 = x[0] - np.mean(x)
    p0 = [abs(a0), wd0, zeta0, 0.0 if a0 > 0 else math.pi, float(np.mean(x))]
    theta, cov = optimize.curve_fit(model, time_ - time_[0], x, p0=p0, maxfev=20000)
    std = np.sqrt(np.diag(cov))
    rms = float(np.sqrt(np.mean((model(time_ - time_[0], *theta) - x) ** 2)))
    return {"wn": float(theta[1]), "wn_std": float(std[1]), "zeta": float(abs(theta[2])),
            "zeta_std": float(std[2]), "rms": rms}


def simulate_yaw(theta: Sequence[float], t: np.ndarray, delta: np.ndarray,
                 r0: float) -> tuple[np.ndarray, np.ndarray]:
    """Free RK4 simulation of ``r' = b (delta + delta0) - d1 r - d3 r^3``, ``psi' = r`` (Nomoto
    with ``b = K/T``, ``d1 = 1/T``; Norrbin's ``d3`` is 0 when ``theta`` has three entries),
    the rudder held over each step, from ``(r0, 0)``."""
    b, d1, delta0, d3 = (*theta, 0.0)[:4]
    r, psi = np.empty(len(t)), np.empty(len(t))
    r[0], psi[0] = r0, 0.0
    for k in range(len(t) - 1):
        h, force = t[k + 1] - t[k], b * (delta[k] + delta0)
        r1 = r[k]
        k1 = force - d1 * r1 - d3 * r1**3
        r2 = r[k] + 0.5 * h * k1
        k2 = force - d1 * r2 - d3 * r2**3
        r3 = r[k] + 0.5 * h * k2
        k3 = force - d1 * r3 - d3 * r3**3
        r4 = r[k] + h * k3
        k4 = force - d1 * r4 - d3 * r4**3
        r[k + 1] = r[k] + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        psi[k + 1] = psi[k] + h * (r1 + 2 * r2 + 2 * r3 + r4) / 6
        if not math.isfinite(r[k + 1]) or abs(r[k + 1]) > 10:
            r[k + 1:], psi[k + 1:] = r[k + 1], psi[k + 1]  # diverged: freeze (a large error)
            break
    return r, psi


def _nomoto(theta: np.ndarray) -> dict[str, float]:
    """``b, d1, delta0[, d3]`` as Nomoto's K, T (and Norrbin's r^3 coefficient)."""
    b, d1, delta0, *d3 = theta.tolist()
    return {"K": b / d1, "T": 1 / d1, "delta0": delta0, **({"d3": d3[0]} if d3 else {})}


def _decimated(rec: Recording, factor: int) -> tuple[np.ndarray, ...]:
    """Time, the rudder's mean over each step (held) and r, psi sampled every ``factor``."""
    n = len(rec.time) // factor * factor
    delta = rec.inputs[:n, 0].reshape(-1, factor).mean(axis=1)
    r, psi = rec.data["r"].to_numpy()[:n:factor], rec.data["psi"].to_numpy()[:n:factor]
    return rec.time[:n:factor], delta, r, psi


def yaw_leave_one_out(recordings: Sequence[Recording]) -> list[dict[str, Any]]:
    """Nomoto and Nomoto-Norrbin fitted to the yaw rate of all tests but one in free simulation
    (d1 of either sign: the hull may be course-unstable), free-simulated on that one: heading
    RMS error, deg, of each and the cut. (Fitted to heading and yaw rate together instead,
    Norrbin extrapolates worse than Nomoto to the 20/5 test: 12.9 -> 19.4 deg.)"""
    runs = [_decimated(rec, ZIGZAG_DECIMATION) for rec in recordings]

    def residuals(theta: np.ndarray, train: Sequence[tuple[np.ndarray, ...]]) -> np.ndarray:
        """Free-simulation yaw-rate errors, each test's mean square counting once."""
        return np.concatenate([(simulate_yaw(theta, t, delta, r[0])[0] - r) / math.sqrt(len(t))
                               for t, delta, r, _ in train])

    rows = []
    for k, rec in enumerate(recordings):
        train = [run for j, run in enumerate(runs) if j != k]
        linear = optimize.least_squares(residuals, [-0.008, 0.1, 0.0], args=(train,)).x
        norrbin = optimize.least_squares(residuals, [*linear, 0.0], args=(train,)).x
        t, delta, r, psi = runs[k]
        errors = [math.degrees(math.sqrt(np.mean((simulate_yaw(th, t, delta, r[0])[1] - psi)
                                                 ** 2))) for th in (linear, norrbin)]
        rows.append({"held_out": rec.meta["name"], "linear_deg": errors[0],
                     "norrbin_deg": errors[1], "cut": 1 - errors[1] / errors[0],
                     "linear": _nomoto(linear), "norrbin": _nomoto(norrbin)})
    return rows
