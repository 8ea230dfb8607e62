"""Loading of the EPFL hovercraft runs: burst stamps, glitches, yaw unwrapping, the usable
span and resampling onto the 10 Hz command time base, in the model's frame (see
``hovercraft_epfl`` for the frame and thruster mapping)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

from .common import DECIMATION, FS_IN, FS_OUT

HOVER_DIR = "hovercraft_epfl"
BURST = 0.002  #: pose stamps closer than this came in one burst from the VRPN client, s
POLL = 0.010  #: VRPN client polling period (the stamps are quantised to it), s
YAW_GLITCH = 0.3  #: a yaw sample this far (rad) from its neighbours' median is a glitch
POS_GLITCH = 0.05  #: likewise for a position sample, m
MAX_GAP = 0.35  #: pose gaps longer than this (s) end the usable part of a run


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

