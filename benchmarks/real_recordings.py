"""Mismatch diagnosis (:func:`estimators.diagnosis.diagnose`) on every real recording we have,
with plain reference fits that do not use the diagnosis.

One Markdown row per diagnosis: case, recordings, model, ``--calibrate``, verdict, top findings
(effect on target, key coefficient ± std), the final model's standard form, calibrated values
± std, held-out RMS error before → after (angles in deg, rates in deg/s, positions in m), the
held-out improvement and the seconds it took. Cases (``--cases``):

1. ``roll-decay``: the shipped KVLCC2 roll decay (10 Hz), model ``usv`` from its DEFAULT
   parameters (the recording's own ``params`` are dropped), ``calibrate="wn,zeta"``. Reference:
   a least-squares fit of ``phi = A exp(-zeta wn t) cos(wd t + phase) + offset`` to the whole
   record (scipy ``curve_fit``).
2. ``sampling``: the original 100 Hz decay (``--shared``/roll_decay_kvlcc2), cut at the release
   with the tail mean removed as ``examples/real_data/kvlcc2.py`` does, at 100, 20 and 10 Hz
   (``resample_poly``) and the 10 Hz version cut to its first 80 %.
3. ``nominal-zeta``: the shipped decay with nominal zeta 0, 0.5, 1 and 2 times the LS fit's
   (wn at the default), calibrating wn, zeta.
4. ``zigzag-series``: the three HSVA KVLCC2 zigzags (``--shared``/zigzag_kvlcc2_hsva, read by
   path, never copied) as one series for ``nomoto``, ``calibrate="K,T"``, ``method="free"``, and
   each alone. Reference (own code): Nomoto ``r' = b (delta + delta0) - d1 r`` (K = b/d1,
   T = 1/d1) and the same with Norrbin's ``- d3 r^3``, fitted (``least_squares``) to the yaw
   rate of two tests in free RK4 simulation at 4 Hz and simulated freely on the third from its
   measured start: heading RMS error of each and the cut.
5. ``hovercraft-epfl``: the two shipped EPFL hovercraft runs (their metadata carries
   hovercraft_epfl_params.json) as one series, ``method="free"``, no ``--calibrate``: free
   simulation cannot follow whole runs, so the diagnosis calibrates the parameters it chooses
   itself on windows it follows, then diagnoses there. Held out: the three runs the converter
   checks on (``--shared``/hovercraft_epfl, read by path with the shipped runs' conversion,
   never copied), free-simulation RMS over the same windows with the nominal and the
   calibrated parameters.
6. ``zigzag-classes``: the four HSVA amplitude classes (10/10, 20/5, 35/5, 10/1; read with
   ``marine_envs.readers.read_hsva_zigzag(path, model="mmg")``), each in turn the training
   class: Nomoto with K, T, delta0 fitted (yaw rate, free simulation, 4 Hz), MMG with the
   published coefficients and MMG with ``MMG_CALIBRATE`` fitted the same way. Every other class
   is re-run as its zigzag (A, B, rudder rate, first direction, approach speed and propeller
   speed read off the record) and replayed with its recorded rudder and propeller: heading RMS
   and first / second overshoot errors against the record; about 30 s of CPU.

7. ``decay-spread``: the shipped decay and the 100 Hz original (one condition), each alone,
   each coefficient refitted on three consecutive pieces of the record by amplitude.
8. ``validate``: ``marine validate``'s tables: the shipped decay's diagnosis predicting the
   100 Hz original at 20 Hz; Nomoto and MMG diagnosed on the 20/5 and 35/5 zigzags predicting
   the 10/10 and 10/1 tests, replayed and re-run as zigzags.

Acceptance targets (from the issue), checked at the end:

- roll decay: calibrated wn within 2 % and zeta within 20 % of the plain LS linear fit; top
  finding amplitude-dependent damping and/or cubic restoring on p, held-out improvement >= 50 %;
- the same top finding at 100/20/10 Hz and on 80 % of the record, and with nominal zeta anywhere
  in [0, 2x] the LS fit's;
- decay spread: each coefficient's reported uncertainty u covers its values on the record's
  pieces and on the other record of the condition (all within 2 u combined with theirs);
- zigzag series: top finding nonlinear yaw damping on r (r^3 or r|r|); leave-one-out
  free-simulation heading error cut >= 30 % (the diagnosis's pooled psi RMS before → after);
- zigzag classes (held-out pairs only): the calibrated MMG's mean heading RMS re-run as the
  zigzag >= 30 % below the calibrated Nomoto's, no predicted class (mean over the training
  classes) worse than Nomoto's by more than 10 %, first-overshoot error <= 2 deg on average.

Exit code 1 when a target is missed. Run time: about 5-10 minutes for all cases.

    python benchmarks/real_recordings.py [--cases roll-decay,zigzag-series] [--shared PATH]
                                         [--json out.json] [--docs [PAGE]]

The HSVA zigzags and the 100 Hz roll decay are not ours to redistribute: they are read by path
from the shared data folder (``--shared``), never copied, and only the results are published.
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
import traceback  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path  # noqa: E402
from scipy import optimize, signal  # noqa: E402

from estimators.diagnosis import diagnose  # noqa: E402
from estimators.diagnosis.validation import validate  # noqa: E402
from marine_envs import manoeuvres  # noqa: E402
from marine_envs.files import write_json  # noqa: E402
from marine_envs.models import get_model  # noqa: E402
from marine_envs.readers import read_hsva_zigzag  # noqa: E402
from marine_envs.recording import Recording, read_recording  # noqa: E402

TITLE = "Diagnosis of real recordings"
ABOUT = """\
The mismatch diagnosis (`estimators.diagnosis.diagnose`) on every real recording the project
has, each against a plain reference fit that does not use the diagnosis: the shipped KVLCC2
roll decay (model `usv` from its default parameters, calibrating `wn, zeta`; reference: a
least-squares fit of a linear decay), the original 100 Hz decay at 100, 20 and 10 Hz and on
80 % of the record, the shipped decay from four nominal dampings, the three HSVA KVLCC2 zigzags
as one series for `nomoto` (calibrating `K, T`; reference: Nomoto and Nomoto-Norrbin fitted in
free simulation, leave one test out), the two shipped EPFL hovercraft runs (calibrated by the
diagnosis itself on the windows it follows, then checked on three runs not shipped), and the four
HSVA amplitude classes each fitted on and predicting the others with Nomoto and the MMG model
(`zigzag-classes`). The HSVA zigzags, the 100 Hz decay and the other hovercraft runs are read by
path from the shared data folder, never copied into the repository: only these results are
published. Each row gives the verdict, the top findings, the calibrated values, the held-out RMS
error before and after, and the seconds it took; the acceptance targets are checked at the end."""

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / "marine_envs" / "data" / "real"
DECAY = REAL / "kvlcc2_roll_decay.csv"
HOVERCRAFT = sorted(REAL.glob("hovercraft_epfl_2019-*.csv"))
ROLL_100HZ = Path("roll_decay_kvlcc2") / "model_test_21338.csv"
ZIGZAG_DIR = Path("zigzag_kvlcc2_hsva")
ZIGZAGS = ("HSVA_CPMC_KVLCC2_Z_10_10_S.dat", "HSVA_CPMC_KVLCC2_Z_20_05.dat",
           "HSVA_CPMC_KVLCC2_Z_35_05.dat")
HOVER_DIR = Path("hovercraft_epfl")
HOVER_CPU_TARGET = 180.0  #: s of CPU for the hovercraft series, calibrated and diagnosed
#: The runs not shipped that the converter checks on (examples/real_data/hovercraft_epfl.py's
#: HOVER_CHECK_RUNS; 11-35-57 is left out there: its tracking is corrupt from 10 to 15 s).
HOVER_HELD_OUT = ("2019-04-16-11-30-28", "2019-04-16-11-32-20", "2019-04-16-12-29-28")
CASES = ("roll-decay", "sampling", "nominal-zeta", "zigzag-series", "hovercraft-epfl",
         "zigzag-classes", "decay-spread", "validate")
#: Effects that make a decay amplitude-dependent (roll-decay target).
AMPLITUDE_EFFECTS = ("quadratic_damping", "nonlinear_damping", "nonlinear_restoring")
#: Effects that are nonlinear yaw damping (zigzag target).
YAW_DAMPING_EFFECTS = ("quadratic_damping", "nonlinear_damping")
WN_TOLERANCE, ZETA_TOLERANCE, IMPROVEMENT_TARGET, HEADING_CUT_TARGET = 0.02, 0.20, 0.5, 0.3
TAIL_WINDOW, EDGE_DROP = 60.0, 1.0  # as examples/real_data/kvlcc2.py
ZIGZAG_DECIMATION = 5  # 20 Hz -> 4 Hz for the reference fits


# -- reading --------------------------------------------------------------------------------------
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


# -- reference fits -------------------------------------------------------------------------------
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


# -- diagnosing -----------------------------------------------------------------------------------
def _final_value(name: str, quality: dict[str, Any]) -> str:
    """A refitted value with its std, flagged when poorly identified; "not determined" when its
    std reaches its size (a value the findings leave undetermined is not shown)."""
    value, std = quality["value"], quality["std"]
    if not std < abs(value):  # NaN and inf too
        return f"{name} not determined"
    text = f"{name}={_fmt(value)} ± {_fmt(std)}"
    return text if quality["status"] == "identified" else text + " (poorly identified)"


def _fmt(value: float) -> str:
    return f"{value:.3g}"


def _convert(rec: Recording, channel: str, value: float) -> tuple[float, str]:
    """An RMS value of ``channel`` in deg or deg/s for angles and rates, SI otherwise."""
    unit = rec.units.get(channel, "")
    if unit.startswith("rad"):
        return math.degrees(value), unit.replace("rad", "deg")
    return value, unit


def run_diagnosis(case: str, recordings: Sequence[Recording], model: str, calibrate: str = "",
                  method: str = "auto", **kwargs: Any) -> dict[str, Any]:
    """One diagnosis, timed, as a table row (its exception, if any, as the verdict)."""
    names = ", ".join(str(r.meta.get("name", "?")) for r in recordings)
    row: dict[str, Any] = {"case": case, "recordings": names, "model": model,
                           "calibrate": calibrate, "method": method}
    start = time.perf_counter()
    try:
        d = diagnose(list(recordings), model, calibrate=calibrate, method=method, **kwargs)
    except Exception as exc:  # reported, not hidden: the table says what broke
        row.update(seconds=time.perf_counter() - start, verdict=f"error: {type(exc).__name__}: "
                   f"{exc}", traceback=traceback.format_exc(), findings=[], top=None)
        return row
    row["seconds"] = time.perf_counter() - start
    row["verdict"] = {True: "mismatch" if d.findings else "mismatch, unexplained by the "
                      "catalogue", False: "none"}.get(d.mismatch, f"cannot judge: {d.reason}")
    row["findings"] = [{"effect": f.effect, "target": f.target,
                        "key": "b" if "b" in f.parameters else "c",
                        "value": f.parameters.get("b", f.parameters.get("c")),
                        "std": f.std.get("b", f.std.get("c")), "improvement": f.improvement,
                        "standard_form": f.standard_form} for f in d.findings]
    row["top"] = (d.findings[0].effect, d.findings[0].target) if d.findings else None
    row["calibrated"] = d.calibration_quality.get("parameters", {})
    row["converged"] = d.calibration_quality.get("converged")
    row["rms"] = {}
    for stage in ("before", "after"):
        for channel, value in d.fit.get(stage, {}).get("rmse", {}).items():
            converted, unit = _convert(recordings[0], channel, value)
            row["rms"].setdefault(channel, {"unit": unit})[stage] = converted
    row["improvement"] = d.fit.get("improvement")
    # the calibrated names refitted with the terms: value, std, status
    row["final_values"] = d.calibration_quality.get("with_findings", {})
    row["diagnosis"] = d.to_dict()
    return row


def check_decay(row: dict[str, Any], reference: dict[str, float]) -> None:
    """Add the wn (2 %) and zeta (20 %) checks against the LS fit to a decay row."""
    cal = row.get("calibrated", {})
    if "wn" in cal and "zeta" in cal:
        row["wn_ok"] = abs(cal["wn"]["value"] / reference["wn"] - 1) <= WN_TOLERANCE
        row["zeta_ok"] = abs(cal["zeta"]["value"] / reference["zeta"] - 1) <= ZETA_TOLERANCE
    row["ls_fit"] = reference


# -- the cases ------------------------------------------------------------------------------------
def case_roll_decay(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    rec = shipped_decay()
    reference = linear_decay_fit(rec.time, rec.data["phi"].to_numpy())
    notes.append(f"roll-decay LS linear fit (whole record, curve_fit): wn = "
                 f"{reference['wn']:.4f} ± {reference['wn_std']:.1e} rad/s, zeta = "
                 f"{reference['zeta']:.5f} ± {reference['zeta_std']:.1e}, RMS residual "
                 f"{math.degrees(reference['rms']):.3f} deg")
    row = run_diagnosis("roll-decay", [rec], "usv", "wn,zeta")
    check_decay(row, reference)
    return [row]


def case_sampling(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    path = shared / ROLL_100HZ
    if not path.is_file():
        notes.append(f"sampling: skipped, {path} is absent")
        return []
    rows = []
    for label, rec in decay_versions(path).items():
        row = run_diagnosis(f"sampling {label}", [rec], "usv", "wn,zeta")
        check_decay(row, linear_decay_fit(rec.time, rec.data["phi"].to_numpy()))
        rows.append(row)
    notes.append(_same_top("sampling", rows))
    return rows


def case_nominal_zeta(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    rec = shipped_decay()
    reference = linear_decay_fit(rec.time, rec.data["phi"].to_numpy())
    rows = []
    for factor in (0.0, 0.5, 1.0, 2.0):
        zeta = factor * reference["zeta"]
        row = run_diagnosis(f"nominal zeta {factor:g}x = {zeta:.5f}", [rec], "usv", "wn,zeta",
                            params={"zeta": zeta})
        check_decay(row, reference)
        rows.append(row)
    notes.append(_same_top("nominal-zeta", rows))
    return rows


def case_zigzag(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    paths = [shared / ZIGZAG_DIR / name for name in ZIGZAGS]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        notes.append(f"zigzag-series: skipped, absent: {', '.join(map(str, missing))}")
        return []
    recordings = [read_hsva_zigzag(p) for p in paths]
    rows = [run_diagnosis("zigzag-series", recordings, "nomoto", "K,T", "free")]
    small = shared / ZIGZAG_DIR / ZIGZAG_CLASSES[-1]
    if small.is_file():  # the four amplitude classes: does the correction hold across them?
        rows.append(run_diagnosis("zigzag-series, four classes",
                                  [*recordings, read_hsva_zigzag(small)], "nomoto", "K,T",
                                  "free"))
    notes += [line for row in rows for line in _across_notes(row)]
    rows += [run_diagnosis(f"zigzag {p.stem.split('_Z_')[1]} alone", [rec], "nomoto", "K,T",
                           "free") for p, rec in zip(paths, recordings, strict=True)]
    start = time.perf_counter()
    loo = yaw_leave_one_out(recordings)
    rows[0]["reference"] = loo
    notes.append(f"zigzag reference (own code, {time.perf_counter() - start:.0f} s): "
                 "leave-one-out free-simulation heading RMS, Nomoto -> Nomoto + Norrbin r^3:")
    for item in loo:
        notes.append(f"  held out {item['held_out']}: {item['linear_deg']:.1f} deg -> "
                     f"{item['norrbin_deg']:.1f} deg (cut {item['cut']:.0%}); linear "
                     + ", ".join(f"{k}={_fmt(v)}" for k, v in item["linear"].items())
                     + "; Norrbin " + ", ".join(f"{k}={_fmt(v)}"
                                                for k, v in item["norrbin"].items()))
    notes.append(f"  mean cut {np.mean([item['cut'] for item in loo]):.0%} (the issue quotes "
                 "linear 12-30 deg off, Norrbin cuts 14/78/55 %)")
    return rows


def _across_notes(row: dict[str, Any]) -> list[str]:
    """The diagnosis's own leave-one-amplitude-class-out validation, in lines."""
    across = row.get("diagnosis", {}).get("across_classes") or {}
    if not across:
        return []
    key = "rerun_rmse" if across.get("judged") == "re-run" else "rmse"
    lines = [f"{row['case']}: across amplitude classes ({across['judged']}), heading RMS "
             "nominal-calibrated -> corrected" + (", richer hosts" if across.get("richer")
                                                   else "") + ":"]
    for c in across["classes"]:
        richer = ", ".join(f"{name} {math.degrees(v[key]['psi']):.2f}"
                           for name, v in c.get("richer", {}).items() if key in v)
        lines.append(f"  {c['class']}: {math.degrees(c['nominal'][key]['psi']):.2f} -> "
                     f"{math.degrees(c['corrected'][key]['psi']):.2f} deg"
                     + (f"; {richer} deg" if richer else "") + (" (worse)" if c["worse"] else ""))
    lines += [f"  {text}" for text in (across.get("verdict"), *across.get("richer", {}).values())
              if text]
    return lines


def case_hovercraft(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    recordings = shipped_hovercraft()
    notes.append("hovercraft-epfl: parameters from the recordings' metadata (the same overrides "
                 "as hovercraft_epfl_params.json); diagnose merges the first recording's params")
    start = time.process_time()
    row = run_diagnosis("hovercraft-epfl", recordings, "hovercraft", "", "free")
    row["cpu_seconds"] = time.process_time() - start
    own = row.get("diagnosis", {}).get("model_check", {}).get("self_calibration")
    if own:
        notes.append(f"hovercraft-epfl: {own['why']}; calibrated by itself in "
                     f"{row['cpu_seconds']:.0f} s of CPU: " + ", ".join(
                         f"{n} = {_fmt(q['value'])} ± {_fmt(q['std'])} ({q['status']})"
                         for n, q in own["chosen_by_sensitivity"].items()))
        held_out = hovercraft_held_out(shared, recordings[0].params, row)
        row["held_out_runs"] = held_out
        notes += [f"  held-out run {h['run']}: free simulation over {own['window_s']:.3g}-s "
                  f"windows, nominal -> calibrated: " + ", ".join(
                      f"{c} {_fmt(v['nominal'])} -> {_fmt(v['calibrated'])} {v['unit']}"
                      for c, v in h["rms"].items()) for h in held_out]
        if not held_out:
            notes.append(f"  held-out runs skipped: {shared / HOVER_DIR} is absent")
    return [row]


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


def hovercraft_held_out(shared: Path, params: dict[str, float],
                        row: dict[str, Any]) -> list[dict[str, Any]]:
    """Per held-out run, the RMS free-simulation error per channel over the diagnosis's windows
    (each from its own fitted start, as the diagnosis judges), with the nominal and the
    self-calibrated parameters (angles in deg)."""
    from estimators.diagnosis.output_error import Series, Structure
    from estimators.diagnosis.self_calibration import grown_fit, windowed
    from marine_envs.models import get_model

    d = row["diagnosis"]
    calibrated = {n: q["value"] for n, q in d["calibration_quality"]["parameters"].items()}
    window = d["model_check"]["self_calibration"]["window_s"]
    out = []
    for rec in unshipped_hovercraft(shared, params):
        rms: dict[str, dict[str, Any]] = {}
        for label, values in (("nominal", params), ("calibrated", {**params, **calibrated})):
            model = get_model("hovercraft", **values)
            series = Series.from_recordings([rec], model)
            series = windowed(series, max(1, round(window / series.dt)))
            structure = Structure(series)
            theta = grown_fit(structure, structure.start()).theta
            errors = np.concatenate([structure.simulate(theta, k)[0] - r.y
                                     for k, r in enumerate(series.runs)])
            for j, channel in enumerate(series.channels):
                value, unit = _convert(rec, channel, float(np.sqrt(np.mean(errors[:, j]**2))))
                rms.setdefault(channel, {"unit": unit})[label] = value
        out.append({"run": rec.meta["name"], "rms": rms})
    return out


# -- zigzag classes: fit on one amplitude class, predict the others -------------------------------
#: The four HSVA amplitude classes (``zigzag-classes``): 10/10, 20/5, 35/5 and 10/1.
ZIGZAG_CLASSES = (*ZIGZAGS, "HSVA_CPMC_KVLCC2_Z_10_01.dat")
#: MMG parameters calibrated on the training class, chosen BEFORE any held-out comparison was
#: run, for what the published coefficients cannot know about the HSVA model: its rudder force
#: (f_alpha: the HSVA rudder/propeller differ from the captive-test model's), its linear yaw
#: damping (N_r: the KVLCC2 is nearly course-unstable, so the zigzag overshoots hinge on it) and
#: its rudder offset (delta0: issue 58 found -0.4 deg on the small-amplitude series).
MMG_CALIBRATE = ("f_alpha", "N_r", "delta0")
#: Acceptance of the classes case (the issue): MMG's mean held-out heading RMS at least 30 %
#: below the calibrated Nomoto's, no class worse by more than 10 %, first-overshoot error
#: <= 2 deg on average.
CLASS_CUT_TARGET, CLASS_WORSE_LIMIT, OVERSHOOT_TARGET_DEG = 0.30, 0.10, 2.0
#: Step of the zigzag re-runs and replays, s (the records' 20 Hz).
ZIGZAG_DT = 0.05
#: Rudder motion, rad/s, above which the rudder counts as moving (reading the rate off).
_MOVING = math.radians(5.0)


def zigzag_setup(rec: Recording) -> dict[str, Any]:
    """The zigzag an ``mmg`` record ran, read off it: amplitude A and heading check B (rad),
    rudder rate (rad/s, the median while moving), first direction (+1 port, -1 starboard, HSVA
    sign), approach speed (m/s, mean u before the execute), propeller speed (rev/s, mean), the
    time of the first execute and of the rudder reversals (s). B is the median |heading change|
    where the rudder starts a reversal: the test's B plus what the heading turned during the
    steering delay (0.35-1.5 deg on the HSVA records), i.e. what the record actually did."""
    t, delta = rec.time, rec.inputs[:, 0]
    rate = np.gradient(delta, t)
    moving = np.abs(rate) > _MOVING
    execute = int(np.argmax(moving))
    amplitude = float(np.median(np.abs(delta[np.abs(delta) > 0.9 * np.max(np.abs(delta))])))
    # a reversal starts where the rudder, held near +-A, begins to move towards the other side
    held = np.abs(delta) > 0.95 * amplitude
    starts = np.flatnonzero(held[:-1] & ~held[1:] & (np.sign(rate[1:]) == -np.sign(delta[1:])))
    psi = rec.data["psi"].to_numpy()
    change = psi - psi[execute]
    return {"amplitude": amplitude, "switch": float(np.median(np.abs(change[starts]))),
            "rate": float(np.median(np.abs(rate[moving]))),
            "first_direction": float(np.sign(delta[execute + 5] - delta[execute])),
            "speed": float(rec.data["u"].to_numpy()[:execute + 1].mean()),
            "n_p": float(rec.inputs[:, 1].mean()), "execute": float(t[execute]),
            "reversals": t[starts]}


def record_overshoots(rec: Recording, setup: dict[str, Any]) -> tuple[float, float]:
    """First and second overshoot angles (rad) of a record, as :func:`marine_envs.manoeuvres.
    zigzag` defines them: the heading change past B after the 2nd (3rd) execute, the executes
    being where the rudder starts each reversal."""
    t = rec.time
    psi = rec.data["psi"].to_numpy()
    change = psi - np.interp(setup["execute"], t, psi)
    turn = -setup["first_direction"]  # HSVA: a positive (port) rudder turns the heading negative
    cuts = [int(np.searchsorted(t, s)) for s in setup["reversals"][:3]] + [len(t)] * 3
    first = np.max(turn * change[cuts[0]:cuts[1]]) - setup["switch"]
    second = np.max(-turn * change[cuts[1]:cuts[2]]) - setup["switch"]
    return float(first), float(second)


def _model_inputs(model: Any, setup: dict[str, Any]) -> tuple[float | None, np.ndarray]:
    """``speed`` and held ``inputs`` for :func:`~marine_envs.manoeuvres.zigzag`: the record's
    approach speed and propeller speed for MMG; the nominal point for Nomoto."""
    if model.name == "mmg":
        return setup["speed"], np.array([0.0, setup["n_p"]])
    return None, np.zeros(1)


def rerun_zigzag(model: Any, rec: Recording, setup: dict[str, Any]) -> dict[str, float]:
    """``model`` re-run as the record's zigzag (rudder to +-A at the record's rate, reversed at
    the heading check B, first direction as recorded) from the record's first execute: heading
    RMS error (rad) over the record after the execute and the overshoots (rad)."""
    speed, inputs = _model_inputs(model, setup)
    duration = rec.time[-1] - setup["execute"]
    result = manoeuvres.zigzag(
        model, setup["amplitude"], setup["switch"], speed=speed, inputs=inputs,
        duration=ZIGZAG_DT * math.floor(duration / ZIGZAG_DT), dt=ZIGZAG_DT,
        first_direction=int(setup["first_direction"]), turn_sign=-1,
        rudder_rate=setup["rate"])
    return {"rms": _heading_rms(rec, setup["execute"], result.time, result.heading_change),
            "first": result.first_overshoot, "second": result.second_overshoot}


def replay(model: Any, rec: Recording, dt: float = ZIGZAG_DT) -> tuple[np.ndarray, np.ndarray]:
    """``model`` driven by the record's inputs (held over each step of ``dt``, a multiple of the
    record's step) from its first measured state: time and heading (rad)."""
    factor = max(1, int(round(dt / (rec.time[1] - rec.time[0]))))
    n = (len(rec.time) - 1) // factor * factor + 1
    time_ = rec.time[:n:factor]
    inputs = rec.inputs[:n]
    if model.name == "mmg":
        x = np.array([rec.data[s].to_numpy()[0] for s in model.state_names])
        u = inputs[:n - 1].reshape(-1, factor, inputs.shape[1]).mean(axis=1)
    else:
        x = np.array([rec.data["r"].to_numpy()[0], rec.data["psi"].to_numpy()[0]])
        u = inputs[:n - 1, :1].reshape(-1, factor, 1).mean(axis=1)
    states = _integrate(model, x, u, time_[1] - time_[0])
    return time_, states[:, model.state_names.index("psi")]


def _integrate(model: Any, x: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    """RK4 of ``model`` with the inputs ``u[k]`` held over step k: states, one row per step."""
    out, work = np.empty(len(x)), np.empty((3, len(x)))
    d, p = np.zeros(len(model.disturbance_names)), model.constants
    states = np.empty((len(u) + 1, len(x)))
    states[0] = x
    for k in range(len(u)):
        model.equations.rk4(states[k], u[k], d, p, h, 1, out, work)
        if not np.all(np.isfinite(out)) or abs(out[model.state_names.index("r")]) > 1.0:
            states[k + 1:] = states[k]  # diverged: frozen (a large error, not a crash)
            break
        states[k + 1] = out
    return states


def _heading_rms(rec: Recording, start: float, time_: np.ndarray, heading: np.ndarray) -> float:
    """RMS (rad) of the simulated heading change (from ``start`` s of the record, time from 0)
    minus the record's heading change from ``start``."""
    keep = rec.time >= start
    psi = rec.data["psi"].to_numpy()
    measured = psi[keep] - np.interp(start, rec.time, psi)
    simulated = np.interp(rec.time[keep] - start, time_, heading, right=np.nan)
    ok = np.isfinite(simulated)
    return float(np.sqrt(np.mean((simulated[ok] - measured[ok]) ** 2)))


def fit_nomoto(rec: Recording) -> Any:
    """Nomoto K, T, delta0 fitted to the record's yaw rate in free simulation (4 Hz), as
    :func:`yaw_leave_one_out` fits it; the fitted model."""
    t, delta, r, _ = _decimated(rec, ZIGZAG_DECIMATION)

    def residuals(theta: np.ndarray) -> np.ndarray:
        return simulate_yaw(theta, t, delta, r[0])[0] - r

    fit = _nomoto(optimize.least_squares(residuals, [-0.008, 0.1, 0.0]).x)
    return get_model("nomoto", K=fit["K"], T=fit["T"], delta0=fit["delta0"])


def fit_mmg(rec: Recording, names: Sequence[str] = MMG_CALIBRATE) -> Any:
    """The published MMG with ``names`` fitted to the record's yaw rate in free simulation of the
    recorded rudder and propeller (4 Hz), from the record's first state; the fitted model.
    Parameters move as factors of their published values (delta0 in rad)."""
    nominal = get_model("mmg")
    factor = ZIGZAG_DECIMATION
    n = (len(rec.time) - 1) // factor * factor + 1
    r = rec.data["r"].to_numpy()[:n:factor]
    u = rec.inputs[:n - 1].reshape(-1, factor, 2).mean(axis=1)
    x0 = np.array([rec.data[s].to_numpy()[0] for s in nominal.state_names])
    h = rec.time[factor] - rec.time[0]

    def variant(theta: np.ndarray) -> Any:
        return nominal.with_params(**{
            name: value if name == "delta0" else value * getattr(nominal.params, name)
            for name, value in zip(names, theta, strict=True)})

    def residuals(theta: np.ndarray) -> np.ndarray:
        try:
            model = variant(theta)
        except ValueError:  # out of the parameters' physical range
            return np.full(len(r), 1.0)
        return _integrate(model, x0, u, h)[:, 2] - r

    start = [0.0 if name == "delta0" else 1.0 for name in names]
    return variant(optimize.least_squares(residuals, start, diff_step=1e-3).x)


def case_zigzag_classes(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    """Each HSVA amplitude class as the training class: Nomoto (K, T, delta0 fitted), MMG with
    the published coefficients and MMG with :data:`MMG_CALIBRATE` fitted, predicting every
    other class re-run as its zigzag and replayed; one row per (training, predicted) pair."""
    paths = [shared / ZIGZAG_DIR / name for name in ZIGZAG_CLASSES]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        notes.append(f"zigzag-classes: skipped, absent: {', '.join(map(str, missing))}")
        return []
    start = time.process_time()
    records = [read_hsva_zigzag(p, model="mmg") for p in paths]
    nomoto_records = [read_hsva_zigzag(p) for p in paths]
    setups = [zigzag_setup(rec) for rec in records]
    names = [p.stem.split("_Z_")[1] for p in paths]
    published = get_model("mmg")
    truth = [record_overshoots(rec, s) for rec, s in zip(records, setups, strict=True)]
    for name, s, (o1, o2) in zip(names, setups, truth, strict=True):
        side = "port" if s["first_direction"] > 0 else "starboard"
        notes.append(f"zigzag-classes: {name} read off the record: A "
                     f"{math.degrees(s['amplitude']):.2f} deg, B {math.degrees(s['switch']):.2f} "
                     f"deg, rudder rate {math.degrees(s['rate']):.1f} deg/s, first {side}, "
                     f"approach {s['speed']:.3f} m/s at {s['n_p']:.2f} rev/s; overshoots "
                     f"{math.degrees(o1):.1f}, {math.degrees(o2):.1f} deg")
    rows = []
    for k, train in enumerate(names):
        models = {"nomoto": fit_nomoto(nomoto_records[k]), "mmg published": published,
                  "mmg calibrated": fit_mmg(records[k])}
        fitted = {"nomoto": {n: getattr(models["nomoto"].params, n) for n in ("K", "T", "delta0")},
                  "mmg calibrated": {n: getattr(models["mmg calibrated"].params, n)
                                     for n in MMG_CALIBRATE}}
        for j, target in enumerate(names):
            row = {"case": "zigzag-classes", "train": train, "target": target,
                   "held_out": j != k, "fitted": fitted}
            for label, model in models.items():
                rec = records[j] if model.name == "mmg" else nomoto_records[j]
                rerun = rerun_zigzag(model, rec, setups[j])
                t_, heading = replay(model, rec)
                row[label] = {
                    "rerun_rms_deg": math.degrees(rerun["rms"]),
                    "replay_rms_deg": math.degrees(_heading_rms(rec, 0.0, t_, heading)),
                    "first_error_deg": math.degrees(rerun["first"] - truth[j][0]),
                    "second_error_deg": math.degrees(rerun["second"] - truth[j][1])}
            rows.append(row)
    notes.append(f"zigzag-classes: {time.process_time() - start:.0f} s CPU")
    return rows


def case_decay_spread(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    """The shipped 10 Hz decay and the 100 Hz original (one condition), each diagnosed alone
    (``usv``, ``wn,zeta``): every coefficient's value on each piece of the record and on the
    other record within two reported uncertainties (:func:`spread_covered`)."""
    recordings = {"shipped 10 Hz": shipped_decay()}
    path = shared / ROLL_100HZ
    if path.is_file():
        recordings["original 100 Hz"] = decay_versions(path)["100 Hz"]
    else:
        notes.append(f"decay-spread: {path} is absent; the shipped decay alone")
    rows = [run_diagnosis(f"decay-spread {label}", [rec], "usv", "wn,zeta")
            for label, rec in recordings.items()]
    for row in rows:
        row["spread_covered"], lines = spread_covered(row, rows)
        notes += [f"{row['case']}: {line}" for line in lines]
    return rows


def spread_covered(row: dict[str, Any], rows: Sequence[dict[str, Any]]) -> tuple[bool, list[str]]:
    """Whether each coefficient's reported uncertainty u (the larger of its statistical std and
    the spread between the record's pieces) covers its value on every piece (within
    2 sqrt(u^2 + s^2), s the piece's own std) and on the other rows of the same condition
    (within 2 sqrt(u^2 + u'^2)); a line per coefficient."""
    spread = row.get("diagnosis", {}).get("fit", {}).get("between_records")
    if not spread:
        return False, ["no spread between pieces was reported"]
    others = [r["diagnosis"]["fit"]["between_records"]["coefficients"] for r in rows
              if r is not row and r.get("diagnosis", {}).get("fit", {}).get("between_records")]
    ok, lines = True, []
    for label, c in spread["coefficients"].items():
        pairs = [*zip(c["per_record"], c["per_record_std"], strict=True),
                 *((o[label]["value"], o[label]["uncertainty"]) for o in others if label in o)]
        worst = max(abs(v - c["value"]) / max(math.hypot(c["uncertainty"], s), 1e-300)
                    for v, s in pairs)
        ok &= worst <= 2
        lines.append(f"{label} = {_fmt(c['value'])} ± {_fmt(c['uncertainty'])} (statistical "
                     f"{_fmt(c['statistical_std'])}, spread {_fmt(c['spread'])}); pieces "
                     + " -> ".join(_fmt(v) for v in c["per_record"])
                     + f"; farthest value {worst:.1f} combined stds away")
    lines += [swap["sentence"] for swap in spread["swaps"]]
    return ok, lines


def case_validate(shared: Path, notes: list[str]) -> list[dict[str, Any]]:
    """``marine validate``'s tables (:func:`estimators.diagnosis.validation.validate`): the
    shipped decay's diagnosis predicting the 100 Hz original at 20 Hz; the Nomoto and the MMG
    diagnoses of the 20/5 and 35/5 zigzags predicting the 10/10 and 10/1 tests, replayed and
    re-run as zigzags. Notes only (the tables), no rows."""
    decay = run_diagnosis("validate: roll decay", [shipped_decay()], "usv", "wn,zeta")
    others = decay_versions(shared / ROLL_100HZ) if (shared / ROLL_100HZ).is_file() else {}
    targets = [others["20 Hz"]] if others else [shipped_decay()]
    notes.append("validate: the shipped decay's diagnosis (usv, wn,zeta) on "
                 + ("the 100 Hz original at 20 Hz" if others else "itself (original absent)"))
    notes.append(validate(decay["diagnosis"], targets).table())
    paths = {name.split("_Z_")[1][:-4]: shared / ZIGZAG_DIR / name for name in ZIGZAG_CLASSES}
    if not all(p.is_file() for p in paths.values()):
        notes.append("validate: zigzags skipped (absent)")
        return []
    for model, calibrate in (("nomoto", "K,T"), ("mmg", ",".join(MMG_CALIBRATE[:2]))):
        read = {k: read_hsva_zigzag(p, model=model) for k, p in paths.items()}
        row = run_diagnosis(f"validate: {model}", [read["20_05"], read["35_05"]], model,
                            calibrate, method="free")
        notes.append(f"validate: {model} diagnosed on 20_05 and 35_05 (calibrating {calibrate}: "
                     f"{row['verdict']}, findings {[f['effect'] for f in row['findings']]}), "
                     "predicting 10_10_S and 10_01 it never saw:")
        notes.append(validate(row["diagnosis"], [read["10_10_S"], read["10_01"]],
                              rerun="zigzag").table())
    return []


RUNNERS: dict[str, Callable[..., list[dict[str, Any]]]] = {
    "roll-decay": case_roll_decay, "sampling": case_sampling,
    "nominal-zeta": case_nominal_zeta, "zigzag-series": case_zigzag,
    "hovercraft-epfl": case_hovercraft, "zigzag-classes": case_zigzag_classes,
    "decay-spread": case_decay_spread, "validate": case_validate}


def _same_top(case: str, rows: Sequence[dict[str, Any]]) -> str:
    tops = {row["top"] for row in rows}
    same = len(tops) == 1 and None not in tops
    what = " on ".join(next(iter(tops))) if same else ", ".join(
        "none" if t is None else " on ".join(t) for t in sorted(tops, key=str))
    return f"{case}: top effect {'the same in all versions' if same else 'DIFFERS'}: {what}"


# -- reporting ------------------------------------------------------------------------------------
def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def format_row(row: dict[str, Any]) -> str:
    findings = "; ".join(f"{f['effect']} on {f['target']} ({f['key']}={_fmt(f['value'])} ± "
                         f"{_fmt(f['std'])})" for f in row["findings"][:3]) or "-"
    form = row["findings"][-1]["standard_form"] if row["findings"] else {}
    calibrated = ", ".join(f"{n}={_fmt(q['value'])} ± {_fmt(q['std'])}"
                           for n, q in row.get("calibrated", {}).items()) or "-"
    final = row.get("final_values", {})
    if any(abs(q["value"] / row["calibrated"][n]["value"] - 1) > 0.1 for n, q in final.items()):
        calibrated += " (final model: " + ", ".join(
            _final_value(n, q) for n, q in final.items()) + ")"
    rms = ", ".join(f"{c} {_fmt(v['before'])} → {_fmt(v['after'])} {v['unit']}"
                    for c, v in row.get("rms", {}).items() if "before" in v) or "-"
    improvement = row.get("improvement")
    improvement = "-" if improvement is None else (
        improvement if isinstance(improvement, str) else f"{improvement:.0%}")
    flags = ["-" if key not in row else ("PASS" if row[key] else "FAIL")
             for key in ("wn_ok", "zeta_ok")]
    cells = [row["case"], row["recordings"], row["model"], row["calibrate"] or "-",
             row["verdict"], findings,
             ", ".join(f"{k}={_fmt(v)}" for k, v in form.items()) or "-", calibrated, rms,
             improvement, f"{row['seconds']:.1f}", *flags]
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


HEADER = ("| case | recordings | model | --calibrate | verdict | top findings | standard form "
          "(final model) | calibrated ± std | held-out RMS before → after | held-out improvement "
          "| s | wn within 2 % of LS | zeta within 20 % of LS |\n" + "|---" * 10 + "|---:|---|---|")


def acceptance(rows: Sequence[dict[str, Any]]) -> list[tuple[str, bool | None, str]]:
    """(target, passed or None when its case did not run, detail)."""
    by_case = {row["case"]: row for row in rows}
    out: list[tuple[str, bool | None, str]] = []
    decay = by_case.get("roll-decay")
    if decay:
        out.append(("roll decay: wn within 2 % of the LS fit", decay.get("wn_ok", False),
                    _calibrated(decay, "wn")))
        out.append(("roll decay: zeta within 20 % of the LS fit", decay.get("zeta_ok", False),
                    _calibrated(decay, "zeta")))
        top, improvement = decay["top"], decay.get("improvement")
        ok = bool(top and top[0] in AMPLITUDE_EFFECTS and top[1] == "p"
                  and isinstance(improvement, float) and improvement >= IMPROVEMENT_TARGET)
        out.append(("roll decay: top finding amplitude-dependent damping / cubic restoring on "
                    "p, held-out improvement >= 50 %", ok,
                    f"{' on '.join(top) if top else 'none'}, {improvement}"))
    for prefix, what in (("sampling", "same top finding at 100/20/10 Hz and on 80 %"),
                         ("nominal zeta", "same top finding with nominal zeta in [0, 2x]")):
        group = [row for row in rows if row["case"].startswith(prefix)]
        if group:
            tops = {row["top"] for row in group}
            out.append((what, len(tops) == 1 and None not in tops,
                        ", ".join(sorted("none" if t is None else " on ".join(t)
                                         for t in tops))))
    out += [(f"{row['case']}: each coefficient's reported uncertainty covers (2 u) its "
             "pieces and the other record", row["spread_covered"], row["verdict"])
            for row in rows if "spread_covered" in row]
    series = by_case.get("zigzag-series")
    if series:
        top = series["top"]
        out.append(("zigzag series: top finding nonlinear yaw damping on r",
                    bool(top and top[0] in YAW_DAMPING_EFFECTS and top[1] == "r"),
                    " on ".join(top) if top else series["verdict"]))
        psi = series.get("rms", {}).get("psi", {})
        cut = 1 - psi["after"] / psi["before"] if "after" in psi and psi["before"] else None
        out.append(("zigzag series: leave-one-out heading error cut >= 30 %",
                    cut is not None and cut >= HEADING_CUT_TARGET,
                    "n/a" if cut is None else f"{cut:.0%} (reference: mean "
                    f"{np.mean([i['cut'] for i in series.get('reference', [])]):.0%})"))
    hover = by_case.get("hovercraft-epfl")
    if hover:
        own = hover.get("diagnosis", {}).get("model_check", {}).get("self_calibration")
        cpu = hover.get("cpu_seconds", math.inf)
        chosen = ", ".join(own["chosen_by_sensitivity"]) if own else "nothing"
        out.append(("hovercraft: calibrated by the diagnosis itself, then diagnosed, in <= 3 min "
                    "of CPU", bool(own) and not hover["verdict"].startswith("cannot judge")
                    and cpu <= HOVER_CPU_TARGET,
                    f"{cpu:.0f} s of CPU; {chosen} calibrated; {hover['verdict']}"))
    return out


CLASS_MODELS = ("nomoto", "mmg published", "mmg calibrated")
CLASS_HEADER = ("| trained on | predicted | " + " | ".join(
    f"{m}: re-run RMS, replay RMS, overshoot errors" for m in CLASS_MODELS) + " |\n"
    + "|---|---|" + "---|" * len(CLASS_MODELS))


def format_class_row(row: dict[str, Any]) -> str:
    """One (training, predicted) pair: per model the heading RMS re-run as the zigzag and
    replayed (deg) and the first / second overshoot errors of the re-run (deg)."""
    cells = [row["train"], row["target"] + ("" if row["held_out"] else " (fitted on)")]
    for label in CLASS_MODELS:
        v = row[label]
        cells.append(f"{v['rerun_rms_deg']:.1f}, {v['replay_rms_deg']:.1f}; "
                     f"{v['first_error_deg']:+.1f}, {v['second_error_deg']:+.1f}")
    return "| " + " | ".join(cells) + " |"


def class_summary(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Means over the fitted-on pairs and over the held-out ones, per model."""
    lines = ["(mmg published is fitted on no class: its fitted-on and held-out rows are the same "
             "runs)"]
    for held, what in ((False, "fitted-on class"), (True, "held-out classes")):
        group = [row for row in rows if row["held_out"] == held]
        for label in CLASS_MODELS:
            values = {key: np.nanmean([abs(row[label][key]) for row in group])
                      for key in ("rerun_rms_deg", "replay_rms_deg", "first_error_deg",
                                  "second_error_deg")}
            lines.append(f"{what}, {label}: mean heading RMS re-run {values['rerun_rms_deg']:.2f}"
                         f" deg, replayed {values['replay_rms_deg']:.2f} deg; mean |overshoot "
                         f"error| {values['first_error_deg']:.2f} (1st), "
                         f"{values['second_error_deg']:.2f} (2nd) deg")
    for row in rows:
        if not row["held_out"]:
            lines.append(f"fitted on {row['train']}: " + "; ".join(
                f"{label} " + ", ".join(f"{n}={_fmt(float(v))}" for n, v in values.items())
                for label, values in row["fitted"].items()))
    return lines


def class_acceptance(rows: Sequence[dict[str, Any]]) -> list[tuple[str, bool | None, str]]:
    """The issue's targets on the held-out pairs: calibrated MMG against calibrated Nomoto."""
    held = [row for row in rows if row["held_out"] and row["case"] == "zigzag-classes"]
    if not held:
        return []
    rich, simple = "mmg calibrated", "nomoto"
    mean = {m: float(np.mean([row[m]["rerun_rms_deg"] for row in held])) for m in (rich, simple)}
    cut = 1 - mean[rich] / mean[simple]
    targets = sorted({row["target"] for row in held})

    def class_mean(model: str, target: str) -> float:
        return float(np.mean([row[model]["rerun_rms_deg"] for row in held
                              if row["target"] == target]))

    per_class = {t: class_mean(rich, t) / class_mean(simple, t) for t in targets}
    pairs = [row[rich]["rerun_rms_deg"] / row[simple]["rerun_rms_deg"] for row in held]
    worse_pairs = sum(ratio > 1 + CLASS_WORSE_LIMIT for ratio in pairs)
    overshoot = float(np.mean([abs(row[rich]["first_error_deg"]) for row in held]))
    return [
        ("zigzag classes: MMG (calibrated) mean held-out heading RMS >= 30 % below Nomoto's",
         cut >= CLASS_CUT_TARGET, f"{mean[rich]:.2f} vs {mean[simple]:.2f} deg ({cut:.0%} "
         "below)"),
        ("zigzag classes: no held-out class worse than Nomoto by more than 10 %",
         max(per_class.values()) <= 1 + CLASS_WORSE_LIMIT,
         "RMS ratio per predicted class (mean over the training classes): " + ", ".join(
             f"{t} {r:.2f}" for t, r in per_class.items())
         + f"; per (training, predicted) pair {worse_pairs} of {len(pairs)} worse by > 10 % "
         f"(worst {max(pairs):.2f})"),
        ("zigzag classes: first-overshoot error <= 2 deg on average (held out)",
         overshoot <= OVERSHOOT_TARGET_DEG, f"{overshoot:.2f} deg")]


def _calibrated(row: dict[str, Any], name: str) -> str:
    value = row.get("calibrated", {}).get(name, {}).get("value")
    return f"{name} = {_fmt(value) if value is not None else 'n/a'}, LS {_fmt(row['ls_fit'][name])}"


# -- main -----------------------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=",".join(CASES),
                        help="comma-separated subset of: %(default)s")
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared" / "data",
                        help="the shared data folder (default: ../shared/data next to the "
                        "repository: %(default)s)")
    parser.add_argument("--json", type=Path, help="also write every row (with each "
                        "diagnosis's to_dict()), the notes and the acceptance checks as JSON")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    add_docs_option(parser, "real_recordings")
    args = parser.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        parser.error(f"unknown case(s) {unknown}; known: {', '.join(CASES)}")
    check_page_path(parser, args.docs)
    rows: list[dict[str, Any]] = []
    notes: list[str] = []
    with benchmark_run("real_recordings", argv) as bench:
        for case in cases:
            print(f"running {case} ...", file=sys.stderr, flush=True)
            rows += RUNNERS[case](args.shared, notes)
        diagnoses = [row for row in rows if row["case"] != "zigzag-classes"]
        classes = [row for row in rows if row["case"] == "zigzag-classes"]
        if diagnoses:
            bench.show("\n".join([HEADER, *map(format_row, diagnoses)]), "Diagnoses")
        if classes:
            bench.show("\n".join([CLASS_HEADER, *map(format_class_row, classes)]),
                       "Zigzag classes: fitted on one, predicting the others")
            notes += class_summary(classes)
        bench.show("\n".join(notes), "Reference fits and notes", markdown=False)
        for row in rows:
            if "traceback" in row:
                print(f"\n{row['case']} raised:\n{row['traceback']}")
        checks = acceptance(diagnoses) + class_acceptance(classes)
        bench.show("\n".join(f"{'PASS' if passed else 'FAIL'}  {what}: {detail}"
                             for what, passed, detail in checks), "Acceptance", markdown=False)
        print(f"\n{len(diagnoses)} diagnoses, {len(classes)} class pairs in "
              f"{time.perf_counter() - bench.started:.0f} s")
    if args.json:
        write_json(args.json, {"rows": rows, "notes": notes, "acceptance": [
            {"target": w, "passed": p, "detail": d} for w, p, d in checks]}, default=str)
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if all(p for _, p, _ in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
