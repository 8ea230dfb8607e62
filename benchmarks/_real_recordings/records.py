"""The real recordings the benchmark diagnoses: the shipped ones, read from
``marine_envs/data/real``, and those read by path from the shared data folder (never copied)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

from marine_envs.recording import Recording, read_recording

REPO = Path(__file__).resolve().parents[2]
REAL = REPO / "marine_envs" / "data" / "real"
DECAY = REAL / "kvlcc2_roll_decay.csv"
HOVERCRAFT = sorted(REAL.glob("hovercraft_epfl_2019-*.csv"))
ROLL_100HZ = Path("roll_decay_kvlcc2") / "model_test_21338.csv"
ZIGZAG_DIR = Path("zigzag_kvlcc2_hsva")
ZIGZAGS = ("HSVA_CPMC_KVLCC2_Z_10_10_S.dat", "HSVA_CPMC_KVLCC2_Z_20_05.dat",
           "HSVA_CPMC_KVLCC2_Z_35_05.dat")
HOVER_DIR = Path("hovercraft_epfl")
#: The runs not shipped that the converter checks on (examples/real_data/hovercraft_epfl.py's
#: HOVER_CHECK_RUNS; 11-35-57 is left out there: its tracking is corrupt from 10 to 15 s).
HOVER_HELD_OUT = ("2019-04-16-11-30-28", "2019-04-16-11-32-20", "2019-04-16-12-29-28")
TAIL_WINDOW, EDGE_DROP = 60.0, 1.0  # as examples/real_data/kvlcc2.py
#: The four HSVA amplitude classes (``zigzag-classes``): 10/10, 20/5, 35/5 and 10/1.
ZIGZAG_CLASSES = (*ZIGZAGS, "HSVA_CPMC_KVLCC2_Z_10_01.dat")


def shipped_decay() -> Recording:
    """The shipped roll decay without its own ``params`` (the model starts at its defaults)."""
    rec = read_recording(DECAY)
    return Recording(rec.data, rec.model, params={}, meta={**rec.meta, "name": DECAY.name})


def shipped_hovercraft() -> list[Recording]:
    """The two shipped hovercraft runs, their metadata's ``params`` kept."""
    return [Recording(rec.data, rec.model, rec.params, {**rec.meta, "name": path.name})
            for path, rec in ((p, read_recording(p)) for p in HOVERCRAFT)]


def decay_versions(path: Path) -> dict[str, Recording]:
    """The original 100 Hz decay cut at the release (largest |phi|), tail mean (whole periods of
    the last 60 s) removed, at 100, 20 and 10 Hz, and the 10 Hz one cut to its first 80 %.
    The resampled versions are filtered on the whole record, phased to keep the release sample,
    and all lose the last second (the filter's edge)."""
    raw = pd.read_csv(path)
    phi, fs = raw["phi"].to_numpy(), 100.0
    release = int(np.argmax(np.abs(phi)))
    tail = np.flatnonzero(raw["time"].to_numpy() >= raw["time"].iloc[-1] - TAIL_WINDOW)
    peaks = tail[signal.find_peaks(signal.savgol_filter(phi[tail], 51, 3))[0]]
    phi = phi - phi[peaks[0]:peaks[-1]].mean()
    out = {}
    for factor in (1, 5, 10):
        start = release % factor
        x = phi[start:] if factor == 1 else signal.resample_poly(phi[start:], 1, factor,
                                                                 padtype="line")
        first, rate = (release - start) // factor, fs / factor
        x = x[first:len(x) - int(EDGE_DROP * rate)]
        out[f"{rate:.0f} Hz"] = _decay_recording(x, rate, f"{path.name} at {rate:.0f} Hz")
    ten = out["10 Hz"].data
    out["10 Hz, first 80 %"] = Recording(ten.iloc[:int(0.8 * len(ten))], "usv",
                                         meta={"name": f"{path.name} at 10 Hz, 80 %"})
    return out


def _decay_recording(phi: np.ndarray, rate: float, name: str) -> Recording:
    time_ = np.arange(len(phi)) / rate
    return Recording.from_arrays("usv", time_, np.zeros(len(phi)), {"phi": phi},
                                 meta={"name": name})


def unshipped_hovercraft(shared: Path, params: dict[str, float]) -> list[Recording]:
    """The held-out EPFL runs, read by path and converted as the shipped ones were
    (examples/real_data: the same loader, frame and thruster mapping; ``params`` theirs)."""
    if not (shared / HOVER_DIR).is_dir():
        return []
    sys.path.insert(0, str(REPO))
    from examples.real_data.hovercraft_epfl_load import load_hover_run
    out = []
    for name in HOVER_HELD_OUT:
        run = load_hover_run(shared, name)
        out.append(Recording.from_arrays(
            "hovercraft", run.time, np.c_[run.sigma_1, run.sigma_2, np.zeros(len(run.time))],
            {"north": run.north, "east": run.east, "psi": run.psi}, params=params,
            meta={"name": f"hovercraft_epfl_{name}"}))
    return out
