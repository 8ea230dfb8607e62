"""KVLCC2 roll decay (SSPA test 21338): extrema, logarithmic decrements and the conversion into
``kvlcc2_roll_decay.csv``."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

from .common import DECIMATION, FS_IN, FS_OUT, _write

KVLCC2_DIR = "roll_decay_kvlcc2"
KVLCC2_FILE = "model_test_21338.csv"
KVLCC2_OUT = "kvlcc2_roll_decay.csv"
TAIL_WINDOW = 60.0  #: the tail whose mean is removed, s (whole periods within it)
EDGE_DROP = 1.0  #: dropped at the end of the record against filter edge effects, s
FIT_PERIODS = 3  #: periods after the release used for the log-decrement estimate of wn, zeta
ATTRIBUTION_KVLCC2 = (
    "SSPA towing tank (MDL), roll decay test 21338 at 0 kn, KVLCC2 model M5057-01-A, scale 1:68, "
    "2018; from the repository martinlarsalbert/Prediction-of-roll-motion-using-fully-nonlinear-"
    "potential-flow-and-Ikedas-method, data/processed/roll decay KVLCC2/model_test_21338.csv. "
    "(c) 2020 Martin Alexandersson, MIT licence (LICENSE-kvlcc2).")


def extrema(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times and values of the alternating extrema of an oscillation, refined by a parabola
    through each sampled extremum and its two neighbours (the first sample counts if it is one)."""
    idx = np.sort(np.r_[signal.find_peaks(x)[0], signal.find_peaks(-x)[0]])
    if abs(x[0]) >= abs(x[1]):
        idx = np.r_[0, idx]
    times, values = [], []
    for i in idx:
        if 0 < i < len(x) - 1:
            a, b, c = x[i - 1], x[i], x[i + 1]
            den = a - 2 * b + c
            off = 0.5 * (a - c) / den if den != 0 else 0.0
            times.append(t[i] + off * (t[1] - t[0]))
            values.append(b - 0.25 * (a - c) * off)
        else:
            times.append(t[i])
            values.append(x[i])
    return np.asarray(times), np.asarray(values)


def log_decrements(t: np.ndarray, x: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-period logarithmic decrements of a free decay.

    Uses peak-to-peak heights ``H_j = |e_j - e_(j+1)|`` of successive extrema (insensitive to a
    residual mean offset); the decrement of period j is ``ln(H_j / H_(j+2))``.

    :return: extremum times and values, the decrements and the mean amplitude (H/2) of each.
    """
    te, ve = extrema(t, x)
    height = np.abs(np.diff(ve))
    decrement = np.log(height[:-2] / height[2:])
    amplitude = 0.25 * (height[:-2] + height[2:])
    return te, ve, decrement, amplitude


def zeta_from_decrement(delta: float) -> float:
    """Damping ratio of a linear oscillator with logarithmic decrement ``delta`` per period."""
    return delta / math.sqrt(4 * math.pi**2 + delta**2)


def convert_kvlcc2(source: Path, out: Path, dry_run: bool) -> None:
    from marine_envs.recording import Recording

    print("== KVLCC2 roll decay (SSPA test 21338)")
    raw = pd.read_csv(source / KVLCC2_DIR / KVLCC2_FILE)
    t_raw, phi_raw = raw["time"].to_numpy(), raw["phi"].to_numpy()
    step = np.diff(t_raw)
    print(f"  original: {len(t_raw)} samples, {t_raw[-1]:.2f} s, step {step.min() * 1e3:.3f} to "
          f"{step.max() * 1e3:.3f} ms (taken as uniform {1e3 / FS_IN:.0f} ms)")
    release = int(np.argmax(np.abs(phi_raw)))
    print(f"  release (largest |phi|) at sample {release}, t = {t_raw[release]:.3f} s, "
          f"phi = {math.degrees(phi_raw[release]):.3f} deg")

    # Mean of the tail over whole periods: between the first and last maxima of the last 60 s.
    tail = t_raw >= t_raw[-1] - TAIL_WINDOW
    peaks = np.flatnonzero(tail)[signal.find_peaks(
        signal.savgol_filter(phi_raw[tail], 51, 3))[0]]
    tail_mean = float(phi_raw[peaks[0]:peaks[-1]].mean())
    print(f"  tail mean ({len(peaks) - 1} whole periods of the last {TAIL_WINDOW:.0f} s): "
          f"{math.degrees(tail_mean):.4f} deg, removed")

    # Anti-alias filter and decimate the whole record (so that the release is not an edge), on a
    # phase such that the release sample is kept, then cut at the release.
    start = release % DECIMATION
    filtered = signal.resample_poly(phi_raw[start:] - tail_mean, 1, DECIMATION, padtype="line")
    first = (release - start) // DECIMATION
    n_keep = int(round((t_raw[-1] - t_raw[release] - EDGE_DROP) * FS_OUT)) + 1
    phi = filtered[first:first + n_keep]
    orig_idx = release + DECIMATION * np.arange(len(phi))
    time = np.round(np.arange(len(phi)) / FS_OUT, 6)
    timing_error = np.abs(t_raw[orig_idx] - t_raw[release] - time).max()
    print(f"  kept {len(phi)} samples at {FS_OUT:.0f} Hz, {time[-1]:.1f} s after the release "
          f"(max deviation of the original sample times from the 0.1 s grid: "
          f"{timing_error * 1e3:.2f} ms)")

    te, ve, dec, amp = log_decrements(time, phi)
    n = 2 * FIT_PERIODS
    delta_fit = math.log(abs(ve[0] - ve[1]) / abs(ve[n] - ve[n + 1])) / FIT_PERIODS
    td = (te[n] - te[0]) / FIT_PERIODS
    zeta = zeta_from_decrement(delta_fit)
    wn = 2 * math.pi / td / math.sqrt(1 - zeta**2)
    print(f"  first {FIT_PERIODS} periods: Td = {td:.4f} s, log decrement {delta_fit:.4f}/period "
          f"-> zeta = {zeta:.4f}, wn = {wn:.4f} rad/s (model scale; full scale wn = "
          f"{wn / math.sqrt(68):.4f} rad/s, T = {td * math.sqrt(68):.1f} s)")
    amp_deg = np.degrees(amp)
    big, small = amp_deg > 7.0, amp_deg < 2.0
    print(f"  log decrement per period: {dec[big].mean():.4f} at amplitudes > 7 deg "
          f"(zeta {zeta_from_decrement(dec[big].mean()):.4f}), {dec[small].mean():.4f} at "
          f"< 2 deg (zeta {zeta_from_decrement(dec[small].mean()):.4f})")
    # Equivalent linearisation of linear + quadratic damping: zeta_eq(A) = z1 + z2 * A
    zeta_eq = np.array([zeta_from_decrement(d) for d in dec])
    z2, z1 = np.polyfit(amp, zeta_eq, 1)
    print(f"  zeta_eq(A) ~ {z1:.4f} + {z2:.4f} * A[rad] (A from {amp_deg.min():.1f} to "
          f"{amp_deg.max():.1f} deg): amplitude-dependent, i.e. nonlinear damping")
    # What the linear model with the fitted wn, zeta predicts at the end of the record
    env_end = abs(ve[0]) * math.exp(-zeta * wn * te[-1])
    print(f"  linear model with these wn, zeta: amplitude after {te[-1]:.0f} s "
          f"{math.degrees(env_end):.3f} deg, measured {math.degrees(abs(ve[-1])):.3f} deg")

    meta = {
        "source": ATTRIBUTION_KVLCC2,
        "licence": "MIT",
        "description": (
            "Free roll decay of a KVLCC2 tanker model (model scale 1:68) at zero speed in calm "
            "water, released from about 10 deg of heel; no rudder or other input. Only the roll "
            "angle is given (sway, yaw and roll rate are not measured). The decay is amplitude-"
            "dependent: a linear roll model with constant zeta fitted to the first periods "
            "decays too fast at small amplitudes (nonlinear, Ikeda-type roll damping)."),
        "sample_rate_hz": FS_OUT,
        "processing": {
            "original_sample_rate_hz": FS_IN,
            "release_time_in_original_s": round(float(t_raw[release]), 4),
            "release_sample_in_original": release,
            "tail_mean_removed_rad": tail_mean,
            "tail_mean_window": f"whole periods of the last {TAIL_WINDOW:.0f} s of the record",
            "filter": ("scipy.signal.resample_poly(x, 1, 10, padtype='line') on the whole "
                       "record (Kaiser-windowed FIR anti-alias filter, zero phase), phased so "
                       "that the release sample is kept; then cut at the release"),
            "end": f"last {EDGE_DROP:.0f} s dropped (filter edge)",
            "rounding": "phi rounded to 1e-8 rad",
            "columns_dropped": "x, y, z, theta, psi (psi drifts slightly; no yaw model input)",
        },
        "params_estimate": (
            f"wn, zeta: logarithmic decrement of peak-to-peak heights over the first "
            f"{FIT_PERIODS} periods after the release (model scale, s)"),
        "initial_state": {"phi": float(phi[0]), "p": 0.0, "v": 0.0, "r": 0.0},
        "scale": 68.0,
    }
    params = {"wn": round(wn, 5), "zeta": round(zeta, 5)}
    rec = Recording.from_arrays("usv", time, np.zeros(len(time)), {"phi": np.round(phi, 8)},
                                params=params, meta=meta)
    _write(rec, out / KVLCC2_OUT, dry_run)
    if not dry_run:
        shutil.copyfile(source / KVLCC2_DIR / "LICENSE", out / "LICENSE-kvlcc2")
