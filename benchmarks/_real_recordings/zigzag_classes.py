"""The ``zigzag-classes`` case: each HSVA amplitude class in turn the training class of Nomoto
and MMG, every other class re-run as its zigzag and replayed; its table and acceptance."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize

from marine_envs import manoeuvres
from marine_envs.models import get_model
from marine_envs.readers import read_hsva_zigzag
from marine_envs.recording import Recording

from .records import ZIGZAG_CLASSES, ZIGZAG_DIR
from .references import ZIGZAG_DECIMATION, _decimated, _nomoto, simulate_yaw
from .rows import _fmt

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
