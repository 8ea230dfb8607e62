"""The cases of the benchmark but the zigzag classes (:mod:`.zigzag_classes`): each reads its
records, diagnoses them (:func:`~.rows.run_diagnosis`) and returns its rows, with notes."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimators.diagnosis.validation import validate
from marine_envs.models import get_model
from marine_envs.readers import read_hsva_zigzag

from .records import (
    HOVER_DIR,
    ROLL_100HZ,
    ZIGZAG_CLASSES,
    ZIGZAG_DIR,
    ZIGZAGS,
    decay_versions,
    shipped_decay,
    shipped_hovercraft,
    unshipped_hovercraft,
)
from .references import linear_decay_fit, yaw_leave_one_out
from .rows import _convert, _fmt, _same_top, check_decay, run_diagnosis
from .zigzag_classes import MMG_CALIBRATE


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


def hovercraft_held_out(shared: Path, params: dict[str, float],
                        row: dict[str, Any]) -> list[dict[str, Any]]:
    """Per held-out run, the RMS free-simulation error per channel over the diagnosis's windows
    (each from its own fitted start, as the diagnosis judges), with the nominal and the
    self-calibrated parameters (angles in deg)."""
    from estimators.diagnosis.output_error import Series, Structure
    from estimators.diagnosis.self_calibration import grown_fit, windowed

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
