"""Convert excerpts of two measured data sets into marine_envs recordings.

Run by hand from the repository root (tests never run it; they read only its outputs)::

    python examples/convert_real_data.py                 # both data sets
    python examples/convert_real_data.py --only kvlcc2   # one of them
    python examples/convert_real_data.py --dry-run       # analyse and print, write nothing

It reads the originals in ``../shared/data`` (outside the package: the project never reads them
at run or test time) and writes into ``marine_envs/data/real/``:

``kvlcc2_roll_decay.csv`` (+ ``.json`` sidecar), model ``usv``
    SSPA roll-decay test 21338 of the KVLCC2 model M5057-01-A (scale 1:68), MIT,
    (c) 2020 Martin Alexandersson. Cut at the release (largest |phi|), the mean of the tail
    removed, low-pass filtered and decimated from 100 Hz to 10 Hz. Columns time, delta (= 0, no
    rudder), phi. The sidecar's ``params`` hold wn and zeta from the logarithmic decrement of the
    first three periods (model scale).

``hovercraft_epfl_<run>.csv`` (+ sidecars), model ``hovercraft``
    Two system-identification runs of a small indoor hovercraft (EPFL, MIT, (c) 2019 Mauro
    Pfister) on the 10 Hz time base of the thrust commands: inputs sigma_1, sigma_2 (the on/off
    thrust commands; frame and mapping below) and delta = 0; measured
    north, east, psi from the motion capture (glitches removed, yaw unwrapped, low-pass filtered
    and resampled). ``hovercraft_epfl_params.json`` holds lab-scale parameter overrides for the
    LCAC-type model, fitted by equation error to both runs.

Frame and thruster mapping of the hovercraft (established from the data, printed when run):
the source's converter writes pose x = OptiTrack z, pose y = OptiTrack x and pose yaw = the
rotation about OptiTrack's vertical y axis (Y-up). The craft accelerates along the direction
(cos yaw, sin yaw) of the (pose x, pose y) plane, so yaw is measured from pose x towards pose y,
which is counter-clockwise seen from above. The NED-like frame of the model (psi clockwise from
above) is therefore north = pose x, east = -pose y, psi = -yaw. In that frame the command the
source labels "left thrust" (field.point.x) yaws the craft to port (r < 0), which is what a
starboard thruster does, so sigma_2 (starboard) = field.point.x and sigma_1 (port) =
field.point.y. Should OptiTrack have streamed a Y-down frame, both the frame and the labels
mirror and the source's labels would be right; the recording is self-consistent either way.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal
from scipy.integrate import solve_ivp

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SOURCE = REPO.parent / "shared" / "data"
DEFAULT_OUT = REPO / "marine_envs" / "data" / "real"

# -- KVLCC2 roll decay -------------------------------------------------------------------------
KVLCC2_DIR = "roll_decay_kvlcc2"
KVLCC2_FILE = "model_test_21338.csv"
KVLCC2_OUT = "kvlcc2_roll_decay.csv"
FS_IN = 100.0  #: original sample rate of both data sets' fast channel, Hz
FS_OUT = 10.0  #: sample rate of the recordings, Hz
DECIMATION = 10
TAIL_WINDOW = 60.0  #: the tail whose mean is removed, s (whole periods within it)
EDGE_DROP = 1.0  #: dropped at the end of the record against filter edge effects, s
FIT_PERIODS = 3  #: periods after the release used for the log-decrement estimate of wn, zeta

# -- EPFL hovercraft ----------------------------------------------------------------------------
HOVER_DIR = "hovercraft_epfl"
HOVER_RUNS = ("2019-04-16-11-24-59", "2019-04-16-11-28-36")
HOVER_CHECK_RUNS = ("2019-04-16-11-30-28", "2019-04-16-11-32-20", "2019-04-16-12-29-28")
HOVER_PARAMS_OUT = "hovercraft_epfl_params.json"
BURST = 0.002  #: pose stamps closer than this came in one burst from the VRPN client, s
POLL = 0.010  #: VRPN client polling period (the stamps are quantised to it), s
YAW_GLITCH = 0.3  #: a yaw sample this far (rad) from its neighbours' median is a glitch
POS_GLITCH = 0.05  #: likewise for a position sample, m
MAX_GAP = 0.35  #: pose gaps longer than this (s) end the usable part of a run
# Source values of the TinyWhoover hovercraft (hovercraft-ros, src/ground/src/controller.py:
# "coefficients estimated in system identification"); m and the lever arm are kept, the rest is
# refitted here.
SOURCE_PARAMS = {"m": 0.0583, "Iz": 89e-6, "d_v": 33e-3, "d_r": 31e-6, "k": 80e-3,
                 "l": 0.0325}
U_T = 15.0  #: speed at which the thrust vanishes, m/s [rough estimate for ~30 mm props]
ATTRIBUTION_KVLCC2 = (
    "SSPA towing tank (MDL), roll decay test 21338 at 0 kn, KVLCC2 model M5057-01-A, scale 1:68, "
    "2018; from the repository martinlarsalbert/Prediction-of-roll-motion-using-fully-nonlinear-"
    "potential-flow-and-Ikedas-method, data/processed/roll decay KVLCC2/model_test_21338.csv. "
    "(c) 2020 Martin Alexandersson, MIT licence (LICENSE-kvlcc2).")
ATTRIBUTION_HOVER = (
    "EPFL indoor hovercraft (TinyWhoover), system-identification run {run} with an on/off "
    "pseudo-random binary thrust sequence and OptiTrack motion capture; from the repository "
    "MauroPfister/hovercraft-ros at commit 73bd403, data_id/controls_{run}.csv and "
    "data_id/pose_{run}.csv. (c) 2019 Mauro Pfister, MIT licence (LICENSE-hovercraft-epfl).")


def _write(recording, path: Path, dry_run: bool) -> None:
    from marine_envs.recording import read_recording, write_recording

    if dry_run:
        print(f"  (dry run: not writing {path})")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    write_recording(recording, path)
    back = read_recording(path)  # the shipped file must read back as a valid recording
    print(f"  wrote {path.relative_to(REPO) if path.is_relative_to(REPO) else path} "
          f"({path.stat().st_size / 1e3:.0f} kB, {len(back.data)} rows)")


# ==============================================================================================
# KVLCC2
# ==============================================================================================
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


# ==============================================================================================
# EPFL hovercraft
# ==============================================================================================
@dataclass
class HoverRun:
    """One hovercraft run on the 10 Hz command time base, in the model's NED-like frame."""

    run: str
    time: np.ndarray  #: s from the first kept command
    sigma_1: np.ndarray  #: port thrust command (source field.point.y), 0/1
    sigma_2: np.ndarray  #: starboard thrust command (source field.point.x), 0/1
    north: np.ndarray  #: m
    east: np.ndarray  #: m
    psi: np.ndarray  #: rad, unwrapped, clockwise from above
    t0_stamp: float  #: ROS time of the first kept command, s
    gaps: list[tuple[float, float]]  #: pose gaps > 0.05 s bridged by interpolation, s
    glitches: int  #: pose samples dropped as glitches
    fine: dict[str, np.ndarray]  #: 100 Hz filtered signals (for the fit), same frame


def _local_median_deviation(values: np.ndarray, half: int, circular: bool) -> np.ndarray:
    """Deviation of each sample from the median of its ``2 half + 1`` neighbours (wrapped to
    (-pi, pi] for angles)."""
    n = len(values)
    dev = np.zeros(n)
    for i in range(n):
        lo, hi = max(0, i - half), min(n, i + half + 1)
        diff = values[lo:hi] - values[i]
        if circular:
            diff = np.angle(np.exp(1j * diff))
        dev[i] = -np.median(diff)
    return dev


def _unwrap_with_rate(t: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Unwrap ``yaw`` choosing, at each sample, the 2 pi branch nearest the extrapolation with the
    recent yaw rate, so that gaps of a few tenths of a second in a fast spin keep their turns."""
    out = np.empty_like(yaw)
    out[0] = yaw[0]
    rate = 0.0
    for i in range(1, len(yaw)):
        dt = t[i] - t[i - 1]
        guess = out[i - 1] + rate * dt
        out[i] = yaw[i] + 2 * np.pi * np.round((guess - yaw[i]) / (2 * np.pi))
        j = max(0, i - 5)  # rate over the last ~50 ms
        if t[i] - t[j] > 0.02:
            rate = (out[i] - out[j]) / (t[i] - t[j])
    return out


def _deburst(stamp: np.ndarray) -> np.ndarray:
    """Sample times for pose stamps that arrive in bursts.

    The VRPN client polls every ~10 ms and stamps every frame of a poll alike, so a burst of n
    frames carries one stamp. The frames were captured during the poll interval: spread them
    evenly over the ``POLL`` before the stamp (the last one keeps the stamp).
    """
    t = stamp.copy()
    starts = np.flatnonzero(np.r_[True, np.diff(stamp) > BURST])
    ends = np.r_[starts[1:], len(stamp)]
    for s, e in zip(starts, ends, strict=True):
        n = e - s
        if n > 1:
            t[s:e] = stamp[e - 1] - POLL * (n - 1 - np.arange(n)) / n
    return np.maximum.accumulate(t + 1e-9 * np.arange(len(t)))  # strictly increasing


def load_hover_run(source: Path, run: str) -> HoverRun:
    folder = source / HOVER_DIR
    ctrl = pd.read_csv(folder / f"controls_{run}.csv")
    pose = pd.read_csv(folder / f"pose_{run}.csv")
    tc = ctrl["field.header.stamp"].to_numpy() * 1e-9
    left, right = ctrl["field.point.x"].to_numpy(), ctrl["field.point.y"].to_numpy()
    lift = ctrl["field.point.z"].to_numpy()
    tp = _deburst(pose["field.header.stamp"].to_numpy() * 1e-9)
    px, py = pose["field.point.x"].to_numpy(), pose["field.point.y"].to_numpy()
    yaw = pose["field.point.z"].to_numpy()

    # Glitches: single frames whose yaw has the wrong sign (an Euler-angle ambiguity of the
    # tracker, seen e.g. at 2.38 s of run 11-24-59) or whose position jumps; drop them (twice,
    # for neighbouring glitches).
    keep = np.ones(len(tp), bool)
    for _ in range(2):
        idx = np.flatnonzero(keep)
        bad = (np.abs(_local_median_deviation(yaw[idx], 3, True)) > YAW_GLITCH) | \
              (np.abs(_local_median_deviation(px[idx], 3, False)) > POS_GLITCH) | \
              (np.abs(_local_median_deviation(py[idx], 3, False)) > POS_GLITCH)
        keep[idx[bad]] = False
    glitches = int((~keep).sum())
    tp, px, py, yaw = tp[keep], px[keep], py[keep], _unwrap_with_rate(tp[keep], yaw[keep])

    # Usable span: the lift fan on, commands present, the pose tracked without long gaps.
    gap_after = np.diff(tp)
    long_gaps = np.flatnonzero(gap_after > MAX_GAP)
    t_end = tp[long_gaps[0]] if long_gaps.size else tp[-1]
    on = lift > 0.5
    first = int(np.argmax(on & (tc >= tp[0])))
    # commands on a 0.1 s grid from the first kept one; the k-th is held until the (k+1)-th
    n = int(np.floor((min(t_end, tc[on][-1] + 0.1) - tc[first]) * FS_OUT + 1e-9)) + 1
    grid = tc[first] + np.arange(n) / FS_OUT
    jitter = np.abs(tc[first:first + n] - grid).max()
    if jitter > 0.02 or not on[first:first + n].all():
        raise ValueError(f"{run}: command timing or lift-fan state unexpected (jitter "
                         f"{jitter:.3f} s)")

    # Pose: linear interpolation on a 100 Hz grid phased on the command grid, zero-phase
    # anti-alias filter and decimation to 10 Hz.
    fine_t = tc[first] + np.arange((n - 1) * DECIMATION + 1) / FS_IN
    fine = {name: np.interp(fine_t, tp, v) for name, v in
            (("north", px), ("east", -py), ("psi", -yaw))}
    coarse = {name: signal.resample_poly(v, 1, DECIMATION, padtype="line")[:n]
              for name, v in fine.items()}
    # 100 Hz signals with the same low-pass (for derivatives in the parameter fit)
    lowpass = signal.firwin(101, 0.8 * FS_OUT / 2, fs=FS_IN)
    fine = {name: signal.filtfilt(lowpass, 1.0, v, padtype="odd") for name, v in fine.items()}
    fine["time"] = fine_t - tc[first]
    rel = tp - tc[first]
    gaps = [(round(float(a), 3), round(float(b), 3)) for a, b in zip(rel[:-1], rel[1:],
                                                                     strict=True)
            if b - a > 0.05 and b > 0 and a < (n - 1) / FS_OUT]
    return HoverRun(run, np.round(np.arange(n) / FS_OUT, 6), right[first:first + n].astype(float),
                    left[first:first + n].astype(float), coarse["north"], coarse["east"],
                    coarse["psi"], float(tc[first]), gaps, glitches, fine)


def body_motion(fine: dict[str, np.ndarray], cutoff: float | None = None
                ) -> dict[str, np.ndarray]:
    """Body velocities and the body-frame components of the acceleration from the 100 Hz pose.

    ``a_x = u_dot - v r`` and ``a_y = v_dot + u r`` are what the model's rigid-body equations
    equate to force over mass (no added mass). ``cutoff`` (Hz): an extra zero-phase low-pass of
    the pose before differencing (apply the same one to the regressors of a fit).
    """
    dt = 1.0 / FS_IN
    sig = {k: (_lowpass(fine[k], cutoff) if cutoff else fine[k]) for k in ("north", "east", "psi")}
    d = {k: np.gradient(v, dt) for k, v in sig.items()}
    dd = {k: np.gradient(v, dt) for k, v in d.items()}
    c, s = np.cos(sig["psi"]), np.sin(sig["psi"])
    return {"u": c * d["north"] + s * d["east"], "v": -s * d["north"] + c * d["east"],
            "r": d["psi"], "a_x": c * dd["north"] + s * dd["east"],
            "a_y": -s * dd["north"] + c * dd["east"], "r_dot": dd["psi"],
            "v_north": d["north"], "v_east": d["east"], "a_north": dd["north"],
            "a_east": dd["east"], "psi": sig["psi"]}


def _lowpass(x: np.ndarray, cutoff: float) -> np.ndarray:
    """Zero-phase FIR low-pass at ``cutoff`` Hz of a 100 Hz signal."""
    return signal.filtfilt(signal.firwin(101, cutoff, fs=FS_IN), 1.0, x, padtype="odd")


def _held(run: HoverRun, lag: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The commands (zero-order hold) at the 100 Hz times, acting ``lag`` s late."""
    k = np.clip(np.floor((run.fine["time"] - lag) * FS_OUT + 1e-9).astype(int), 0,
                len(run.time) - 1)
    return run.sigma_1[k], run.sigma_2[k]


FIT_CUTOFF = 2.0  #: low-pass (Hz) applied alike to the pose and the regressors of the fit
INNER = slice(100, -100)  #: samples of the 100 Hz signals used in fits (1 s of filter edge off)


def check_hover_frame(runs: list[HoverRun]) -> None:
    """Print the two checks behind the frame and the thruster mapping."""
    for run in runs:
        b = body_motion(run.fine, FIT_CUTOFF)
        s1, s2 = _held(run, 0.05)
        # force direction (acceleration plus a linear-drag guess v / 2 s) against the heading
        both = (s1 + s2 == 2)[INNER]
        force = np.arctan2(b["a_east"] + b["v_east"] / 2, b["a_north"] + b["v_north"] / 2)
        z = np.exp(1j * (force - b["psi"]))[INNER][both].mean()
        A = np.c_[(s1 - s2), (s1 + s2), np.ones_like(s1)]
        A = np.c_[np.apply_along_axis(_lowpass, 0, A, FIT_CUTOFF), b["r"]][INNER]
        coef = np.linalg.lstsq(A, b["r_dot"][INNER], rcond=None)[0]
        print(f"  {run.run}: with both thrusters on the craft accelerates at "
              f"{math.degrees(np.angle(z)):+.1f} deg from the heading (resultant {abs(z):.2f}); "
              f"r_dot = {coef[0]:+.1f} (sigma_1 - sigma_2) {coef[1]:+.1f} (sigma_1 + sigma_2) "
              f"{coef[2]:+.2f} {coef[3]:+.2f} r [rad/s^2]")


def fit_hover_params(runs: list[HoverRun], lag: float = 0.05) -> tuple[dict[str, float],
                                                                        dict[str, float]]:
    """Lab-scale overrides of the LCAC model by equation error (linear least squares).

    With no added mass, thrust ``T0 sigma (1 - u/U_T)`` and linear drag the model's equations
    are, with ``a_x = u_dot - v r`` and ``a_y = v_dot + u r`` (the body components of the
    acceleration)::

        m a_x    = T0 (s1 + s2)(1 - u/U_T) + X_Hu u
        m a_y    = Y_Hv v
        Iz r_dot = y_P T0 (s1 - s2)(1 - u/U_T) + N_Hr r

    m and y_P are the source's; T0, X_Hu, Y_Hv, Iz and N_Hr follow from the per-mass fits. Pose
    and regressors are low-passed alike (``FIT_CUTOFF``) so that the filter does not bias the
    fit. The commands act ``lag`` s late (motor response). The yaw fit also estimates a constant
    yaw acceleration (not in the model) so that this bias does not leak into the other
    coefficients; it is reported as missing physics.
    """
    eqs: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {
        k: ([], []) for k in ("surge", "sway", "yaw")}
    for run in runs:
        b = body_motion(run.fine, FIT_CUTOFF)
        s1, s2 = _held(run, lag)
        raw = body_motion(run.fine)
        factor = 1 - raw["u"] / U_T

        def lp(*cols: np.ndarray) -> np.ndarray:
            return np.c_[tuple(_lowpass(c, FIT_CUTOFF) for c in cols)][INNER]

        eqs["surge"][0].append(lp((s1 + s2) * factor, raw["u"]))
        eqs["surge"][1].append(b["a_x"][INNER])
        eqs["sway"][0].append(lp(raw["v"]))
        eqs["sway"][1].append(b["a_y"][INNER])
        eqs["yaw"][0].append(lp((s1 - s2) * factor, raw["r"], np.ones_like(s1)))
        eqs["yaw"][1].append(b["r_dot"][INNER])
    coef = {}
    for key, (rows, rhs) in eqs.items():
        A, y = np.concatenate(rows), np.concatenate(rhs)
        c = np.linalg.lstsq(A, y, rcond=None)[0]
        coef[key] = (c, 1 - np.var(y - A @ c) / np.var(y))
    m, y_p = SOURCE_PARAMS["m"], SOURCE_PARAMS["l"]
    (a_t, a_u), r2_u = coef["surge"]
    (b_v,), r2_v = coef["sway"]
    (c_t, c_r, c_0), r2_r = coef["yaw"]
    t0 = a_t * m
    iz = y_p * t0 / c_t
    fitted = {"T0": t0, "X_Hu": a_u * m, "Y_Hv": b_v * m, "Iz": iz, "N_Hr": c_r * iz}
    info = {"r2_surge": r2_u, "r2_sway": r2_v, "r2_yaw": r2_r, "yaw_bias_rad_s2": c_0,
            "yaw_bias_moment_Nm": c_0 * iz, "lag_s": lag}
    return fitted, info


def hover_params(fitted: dict[str, float], u_cruise: float) -> dict[str, float]:
    """The complete override set: the fitted values, the source's m and y_P, no added mass, no
    aerodynamic or nonlinear hull terms, no rudder (the lab craft has none)."""
    from marine_envs.models.hovercraft import HovercraftParams

    zero = [f for f in HovercraftParams.__dataclass_fields__
            if f[:3] in ("X_A", "Y_A", "N_A", "X_H", "Y_H", "N_H") or f.startswith("C_R")]
    params = dict.fromkeys(zero, 0.0)
    params.update({
        "m": SOURCE_PARAMS["m"], "X_ud": 0.0, "Y_vd": 0.0, "N_rd": 0.0, "N_vd": 0.0,
        "y_P": SOURCE_PARAMS["l"], "U_T": U_T, "D_p": 0.031, "L": 0.10, "B": 0.09,
        "S_R": 1e-4, "x_R": -0.05, "k_s": 0.0, "u_cruise": u_cruise,
    })
    params.update(fitted)
    return {k: float(f"{v:.4g}") for k, v in params.items()}


def simulate(model, run: HoverRun, x0: np.ndarray) -> np.ndarray:
    """Open-loop simulation on the recorded inputs (held between samples), states at run.time."""
    u = np.c_[run.sigma_1, run.sigma_2, np.zeros(len(run.time))]
    xs = [x0]
    x = x0
    for k in range(len(run.time) - 1):
        sol = solve_ivp(lambda _t, s, uk=u[k]: model.rhs(s, uk), (0.0, 1 / FS_OUT), x,
                        rtol=1e-6, atol=1e-9)
        x = sol.y[:, -1]
        xs.append(x)
    return np.array(xs)


def compare_hover(model, runs: list[HoverRun], label: str) -> dict[str, dict[str, float]]:
    """Peak and mean speed and yaw rate, recorded vs simulated (open loop, whole run), and the
    median error of 1 s ahead predictions from the recorded state."""
    out = {}
    for run in runs:
        b = body_motion(run.fine)
        at = np.arange(0, len(run.fine["time"]), DECIMATION)
        x_rec = np.c_[b["u"][at], b["v"][at], b["r"][at], run.north, run.east, run.psi]
        sim = simulate(model, run, x_rec[0])
        speed_rec, speed_sim = np.hypot(x_rec[:, 0], x_rec[:, 1]), np.hypot(sim[:, 0], sim[:, 1])
        # 1 s ahead predictions from every recorded state
        err_r, err_speed = [], []
        for k in range(0, len(run.time) - 10, 5):
            sub = HoverRun(run.run, run.time[k:k + 11] - run.time[k], run.sigma_1[k:k + 11],
                           run.sigma_2[k:k + 11], run.north[k:k + 11], run.east[k:k + 11],
                           run.psi[k:k + 11], 0.0, [], 0, {})
            pred = simulate(model, sub, x_rec[k])[-1]
            err_r.append(abs(pred[2] - x_rec[k + 10, 2]))
            err_speed.append(abs(np.hypot(pred[0], pred[1]) - speed_rec[k + 10]))
        stats = {"peak_speed_rec": speed_rec.max(), "peak_speed_sim": speed_sim.max(),
                 "mean_speed_rec": speed_rec.mean(), "mean_speed_sim": speed_sim.mean(),
                 "peak_abs_r_rec": np.abs(x_rec[:, 2]).max(),
                 "peak_abs_r_sim": np.abs(sim[:, 2]).max(),
                 "mean_r_rec": x_rec[:, 2].mean(), "mean_r_sim": sim[:, 2].mean(),
                 "median_err_r_1s": float(np.median(err_r)),
                 "median_err_speed_1s": float(np.median(err_speed))}
        out[run.run] = {k: round(float(v), 3) for k, v in stats.items()}
        print(f"  {label:>7} {run.run}: speed peak {stats['peak_speed_rec']:.2f} rec / "
              f"{stats['peak_speed_sim']:.2f} sim, mean {stats['mean_speed_rec']:.2f} / "
              f"{stats['mean_speed_sim']:.2f} m/s; |r| peak {stats['peak_abs_r_rec']:.1f} / "
              f"{stats['peak_abs_r_sim']:.1f}, mean r {stats['mean_r_rec']:+.2f} / "
              f"{stats['mean_r_sim']:+.2f} rad/s; 1 s ahead median error r "
              f"{stats['median_err_r_1s']:.2f} rad/s, speed {stats['median_err_speed_1s']:.2f} m/s")
    return out


def convert_hovercraft(source: Path, out: Path, dry_run: bool) -> None:
    from marine_envs.models import get_model
    from marine_envs.recording import Recording

    print("== EPFL hovercraft")
    runs = [load_hover_run(source, run) for run in HOVER_RUNS]
    for run in runs:
        print(f"  {run.run}: {len(run.time)} samples ({run.time[-1]:.1f} s), lift fan on "
              f"throughout, {run.glitches} glitch frames dropped, {len(run.gaps)} pose gaps > "
              f"50 ms bridged (longest {max(b - a for a, b in run.gaps):.2f} s)")
    print("  frame check (north = pose x, east = -pose y, psi = -yaw; sigma_1 = field.point.y, "
          "sigma_2 = field.point.x):")
    check_hover_frame(runs)
    fitted, info = fit_hover_params(runs)
    speed = np.concatenate([np.hypot(body_motion(r.fine)["u"], body_motion(r.fine)["v"])
                            for r in runs])
    params = hover_params(fitted, u_cruise=round(float(np.median(speed)), 2))
    print(f"  fit (R^2 surge {info['r2_surge']:.2f}, sway {info['r2_sway']:.2f}, yaw "
          f"{info['r2_yaw']:.2f}): " + ", ".join(f"{k} = {params[k]:.4g}" for k in fitted))
    print(f"  source (hovercraft-ros controller.py): T0 = k = {SOURCE_PARAMS['k']}, X_Hu = Y_Hv "
          f"= -d_v = {-SOURCE_PARAMS['d_v']}, Iz = {SOURCE_PARAMS['Iz']}, N_Hr = -d_r = "
          f"{-SOURCE_PARAMS['d_r']}")
    print(f"  not in the model: constant yaw acceleration {info['yaw_bias_rad_s2']:+.2f} rad/s^2 "
          f"(moment {info['yaw_bias_moment_Nm']:+.2e} N m)")
    model = get_model("hovercraft", **params)
    source_like = dict(params, T0=SOURCE_PARAMS["k"], X_Hu=-SOURCE_PARAMS["d_v"],
                       Y_Hv=-SOURCE_PARAMS["d_v"], Iz=SOURCE_PARAMS["Iz"],
                       N_Hr=-SOURCE_PARAMS["d_r"])
    checks = {"fitted": compare_hover(model, runs, "fitted")}
    checks["source"] = compare_hover(get_model("hovercraft", **source_like), runs, "source")
    checks["LCAC"] = compare_hover(get_model("hovercraft"), runs, "LCAC")

    for run in runs:
        meta = {
            "source": ATTRIBUTION_HOVER.format(run=run.run),
            "licence": "MIT",
            "description": (
                "A ~60 g indoor hovercraft driven by a pseudo-random on/off sequence of its two "
                "thrusters with the lift fan on, tracked by motion capture. Inputs sigma_1 "
                "(port) and sigma_2 (starboard) are the 0/1 thrust commands; there is no rudder "
                "(delta = 0). Only north, east and psi are measured. Known to contain: very "
                "low lateral friction (large sideslip), a constant yaw moment that spins the "
                "craft (lift-fan reaction or motor asymmetry), a thrust direction a few degrees "
                "off the heading, and a motor response delay of about 50 ms."),
            "sample_rate_hz": FS_OUT,
            "run": run.run,
            "processing": {
                "time_base": ("the thrust commands' header stamps: sample k at the k-th "
                              "command after the first with the lift fan on and the pose "
                              "tracked; command k held until sample k+1"),
                "t0_ros_time_s": round(run.t0_stamp, 6),
                "frame": ("north = pose field.point.x, east = -pose field.point.y, psi = "
                          "-unwrapped field.point.z: right-handed with z down if OptiTrack is "
                          "Y-up (the source's converter.py writes pose x = OptiTrack z, pose y "
                          "= OptiTrack x, yaw about OptiTrack y); origin and axes are the "
                          "motion-capture room's"),
                "inputs": ("sigma_1 = field.point.y (labelled 'right thrust' in the source), "
                           "sigma_2 = field.point.x (labelled 'left thrust'): in this frame "
                           "field.point.x yaws the craft to port, as a starboard thruster "
                           "does; sigma = command (0 = off, 1 = on; the model's thrust is "
                           "T0 sigma), delta = 0"),
                "pose": ("bursts of frames with one VRPN stamp spread over the 10 ms poll "
                         "before it; single-frame glitches (mirrored yaw, position jumps) "
                         "dropped; yaw unwrapped with the recent yaw rate across gaps; linear "
                         "interpolation on a 100 Hz grid phased on the commands, then "
                         "scipy.signal.resample_poly(x, 1, 10, padtype='line') "
                         "(zero-phase anti-alias FIR)"),
                "glitch_frames_dropped": run.glitches,
                "pose_gaps_bridged_s": run.gaps,
            },
            "params_fit": {k: float(f"{v:.4g}") for k, v in info.items()},
            "model_check": checks["fitted"][run.run],
            "model_check_note": ("the model with these params simulated open loop over the "
                                 "whole run from the recorded initial state (rec = recording, "
                                 "sim = simulation; speed in m/s, r in rad/s, derived from the "
                                 "100 Hz pose), and the median error of 1 s ahead predictions "
                                 "from recorded states"),
            "params_note": ("params: lab-scale overrides of the LCAC model (see "
                            "hovercraft_epfl_params.json and README.md); m and y_P from the "
                            "source, T0, Iz, X_Hu, Y_Hv, N_Hr fitted by equation error"),
        }
        rec = Recording.from_arrays(
            "hovercraft", run.time, np.c_[run.sigma_1, run.sigma_2, np.zeros(len(run.time))],
            {"north": np.round(run.north, 6), "east": np.round(run.east, 6),
             "psi": np.round(run.psi, 6)}, params=params, meta=meta)
        _write(rec, out / f"hovercraft_epfl_{run.run}.csv", dry_run)
    print("  out of sample (runs not shipped; 11-35-57 is left out, its tracking is corrupt "
          "from 10 to 15 s):")
    compare_hover(model, [load_hover_run(source, run) for run in HOVER_CHECK_RUNS], "fitted")
    if not dry_run:
        (out / HOVER_PARAMS_OUT).write_text(json.dumps(params, indent=2) + "\n",
                                            encoding="utf-8")
        print(f"  wrote {out / HOVER_PARAMS_OUT}")
        shutil.copyfile(source / HOVER_DIR / "LICENSE", out / "LICENSE-hovercraft-epfl")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=("Convert excerpts of the measured KVLCC2 roll-decay and EPFL hovercraft "
                     "data (../shared/data) into marine_envs recordings in "
                     "marine_envs/data/real/. Run by hand; prints the estimates."),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--source", type=Path, default=DEFAULT_SOURCE,
                        help="folder holding roll_decay_kvlcc2/ and hovercraft_epfl/")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    parser.add_argument("--only", choices=("kvlcc2", "hovercraft"),
                        help="convert only one data set")
    parser.add_argument("--dry-run", action="store_true",
                        help="analyse and print, write nothing")
    args = parser.parse_args(argv)
    if not args.source.is_dir():
        parser.error(f"source folder not found: {args.source}")
    sys.path.insert(0, str(REPO))  # run from a checkout without installing
    if args.only in (None, "kvlcc2"):
        convert_kvlcc2(args.source, args.out, args.dry_run)
    if args.only in (None, "hovercraft"):
        convert_hovercraft(args.source, args.out, args.dry_run)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
