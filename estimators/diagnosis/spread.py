"""How far a free-simulation diagnosis holds beyond one record: the spread of its coefficients
between records and its validity across amplitude classes.

* **Between records** (:func:`between_records`): the final model refitted whole on each record
  of the series alone (a single record: on consecutive pieces of it by amplitude, see
  :func:`pieces`). Each coefficient (calibrated parameters, the findings' coefficients, the
  standard form's) gets the spread of its per-record values about it (:func:`record_spread`)
  beside its statistical std; the reported uncertainty is the larger of the two. A record's
  residuals give a std that assumes the model is right; when the coefficient moves with the
  amplitude span, the spread between records is the honest figure. An accepted amplitude term
  whose nearest rival (the other damping or restoring form on the same state) fits some record
  better is named: the data do not tell them apart.
* **Across amplitude classes** (:func:`amplitude_classes`, :func:`across_classes`): records
  whose manoeuvre amplitude (largest input, or a free decay's initial amplitude; a zigzag's
  heading check too) agree within :data:`CLASS_TOLERANCE` form a class; with two classes or
  more each class is free-simulated (its recorded inputs replayed) by the nominal-calibrated and
  the corrected model fitted on the other classes. A correction that makes a held-out class
  worse than the nominal model shows that the host model's class is the limit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from marine_envs.models import get_model
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording

from .comparison import Comparison, Scored, all_rows, extend
from .output_error import Fit, Series, Structure, basis, fit, term_label
from .ranges import standard_form
from .residuals import displacements
from .result import Finding
from .validation import rerun_from_fit

FloatArray = NDArray[np.float64]
#: A single record is cut into this many consecutive pieces by amplitude.
PIECES = 3
#: Two manoeuvre amplitudes (or heading checks) belong to one class when they differ by at
#: most this share of the larger (the HSVA series: 10/10, 20/5, 35/5 and 10/1 are four
#: classes; records of one nominal test differ by a few per cent).
CLASS_TOLERANCE = 0.25
#: A held-out class whose mean square error with the correction exceeds the nominal model's by
#: this share is made worse by it (the issue's acceptance: no class worse by more than 10 %).
WORSE = 0.1
#: Amplitude terms that may swap with the record's span.
AMPLITUDE_EFFECTS = ("quadratic_damping", "nonlinear_damping", "nonlinear_restoring")
#: A decay envelope that falls by less than this factor over the record has no amplitude span
#: to cut by: the pieces are consecutive in time instead.
SPAN = 2.0


# -- pieces ---------------------------------------------------------------------------------------
def pieces(series: Series, count: int = PIECES) -> list[tuple[str, Series]]:
    """Per record of a series, a one-record series (same scales and steps; a record cut into
    windows keeps its windows together, :meth:`Series.folds`); a single record cut into
    ``count`` consecutive pieces at equal ratios of its amplitude envelope (in time when the
    envelope spans less than :data:`SPAN`), each named by its time span."""
    folds = series.folds()
    if len(folds) > 1:
        return [(series.runs[fold[0]].name or f"record {k + 1}",
                 replace(series, runs=[series.runs[i] for i in fold]))
                for k, fold in enumerate(folds)]
    run = series.runs[0]
    cuts = _cuts(run.y / series.scale, run.time, count)
    out = []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        part = replace(run, time=run.time[a:b] - run.time[a], u=run.u[a:b], y=run.y[a:b])
        name = f"{run.time[a]:.0f}-{run.time[b - 1]:.0f} s"
        out.append((name, replace(series, runs=[part])))
    return out


def _cuts(y: FloatArray, time: FloatArray, count: int) -> list[int]:
    """Sample indices bounding ``count`` pieces: where the envelope (the largest scaled
    deviation from the record's end still to come) crosses geometric levels between its first
    value and its value over the last tenth (the last oscillations' amplitude)."""
    n = len(time)
    tenth = max(n // 10, 1)
    deviation = np.max(np.abs(y - np.median(y[-tenth:], axis=0)), axis=1)
    envelope = np.maximum.accumulate(deviation[::-1])[::-1]
    top, bottom = float(envelope[0]), float(max(envelope[n - tenth], 1e-12))
    if top / bottom < SPAN:
        return [round(k * n / count) for k in range(count + 1)]
    levels = top * (bottom / top) ** (np.arange(1, count) / count)
    inner = [int(np.argmax(envelope <= level)) for level in levels]
    return [0, *inner, n]


# -- between records ------------------------------------------------------------------------------
def between_records(comparison: Comparison) -> dict[str, Any]:
    """The final model refitted on each piece (:func:`pieces`): per coefficient its value on
    the whole series, statistical std, the per-piece values and stds, their spread
    (:func:`record_spread`) and the reported ``uncertainty`` (the larger); and the amplitude
    terms that swap with a rival from piece to piece (``swaps``)."""
    final = comparison.final
    structure = final.structure
    parts = pieces(comparison.series)
    refits = [_refit(structure, final, part) for _, part in parts]
    names = [name for name, _ in parts]
    method = (f"the final model refitted whole on each of the {len(parts)} records alone"
              if len(comparison.series.folds()) > 1 else
              f"the final model refitted whole on {len(parts)} consecutive pieces of the record "
              "(cut at equal ratios of its amplitude envelope)")
    whole = coefficients(final)
    per = [coefficients(r) for r in refits]
    table = {}
    for label, (value, std) in whole.items():
        values = [p[label][0] for p in per]
        stds = [p[label][1] for p in per]
        spread = record_spread(value, values)
        table[label] = {"value": value, "statistical_std": std, "spread": spread,
                        "per_record": values, "per_record_std": stds,
                        "uncertainty": max(std, spread)}
    return {"method": method, "records": names, "coefficients": table,
            "swaps": _swaps(comparison, parts, refits)}


def record_spread(value: float, values: Sequence[float]) -> float:
    """The RMS deviation of the per-record values from the whole series' value,
    ``sqrt(mean((v_k - v)^2))``: a whole-series value outside every piece's (a nonlinear trade
    between terms) counts, and each record lies within ``sqrt(n)`` of it. The records' own
    stds are not subtracted: they come from residuals that assume the model is right (on the
    HSVA series, subtracting them left K at 0.088 ± 0.025 while its per-record values were
    0.81, -0.43, 0.078, 0.045)."""
    if len(values) < 2:
        return 0.0
    return float(math.sqrt(np.mean([(v - value) ** 2 for v in values])))


def _refit(structure: Structure, whole: Fit, part: Series) -> Fit:
    """``structure``'s model and terms fitted on ``part`` alone, from the whole fit's values
    (and its fitted initial states for the runs ``part`` shares with it: a window's start is
    not its first sample where states are unmeasured)."""
    own = Structure(part, structure.names, structure.terms, structure.inputs)
    labels = structure.labels()
    start = {label: float(whole.theta[labels.index(label)])
             for label in (*structure.names, *(term_label(t) for t in structure.terms))}
    states = [part.model.state_names[i] for i in structure.free_states]
    for j, run in enumerate(part.runs):
        k = next((i for i, r in enumerate(structure.series.runs) if r is run), None)
        if k is not None:
            start |= {f"{s}0[{j}]": float(whole.theta[labels.index(f"{s}0[{k}]")])
                      for s in states}
    return fit(own, all_rows(part), own.start(start))


def coefficients(result: Fit) -> dict[str, tuple[float, float]]:
    """Value and statistical std of each calibrated parameter, term coefficient and standard
    form coefficient (``"p: C3"``; its std propagated through the covariance)."""
    structure = result.structure
    labels = structure.labels()
    k_end = len(structure.names) + len(structure.terms)
    out = {labels[k]: (float(result.theta[k]), float(result.std[k])) for k in range(k_end)}
    targets = sorted({t.target for t in structure.terms if t.kind == "state"})
    if not targets:
        return out
    form = {t: standard_form(result, t) for t in targets}
    with np.errstate(invalid="ignore"):  # an unidentified unknown's inf std: made 0 below
        covariance = np.outer(result.std[:k_end], result.std[:k_end]) * \
            result.correlation[:k_end, :k_end]
    for target in targets:
        derivative = _form_derivative(result, target, k_end)
        for key, value in form[target].items():
            row = np.array([d.get(key, 0.0) for d in derivative])
            variance = float(row @ np.nan_to_num(covariance) @ row)
            out[f"{target}: {key}"] = (value, math.sqrt(max(variance, 0.0)))
    return out


def _form_derivative(result: Fit, target: str, count: int) -> list[dict[str, float]]:
    """d(standard form)/d(unknown) for the first ``count`` unknowns, by central differences."""
    out = []
    for k in range(count):
        h = 1e-6 * max(abs(float(result.theta[k])), 1e-3)
        forms = []
        for sign in (1.0, -1.0):
            theta = result.theta.copy()
            theta[k] += sign * h
            forms.append(standard_form(replace(result, theta=theta), target))
        out.append({key: (forms[0][key] - forms[1].get(key, 0.0)) / (2 * h) for key in forms[0]})
    return out


def _swaps(comparison: Comparison, parts: Sequence[tuple[str, Series]],
           refits: Sequence[Fit]) -> list[dict[str, Any]]:
    """Per accepted amplitude term, its best rival of the same round on the same state (another
    damping or restoring form): refitted in its place on each piece; named when it fits some
    piece better while the chosen term wins on the whole."""
    out = []
    structure = comparison.final.structure
    for round_, chosen in zip(comparison.rounds, comparison.accepted, strict=False):
        rival = _rival(round_, chosen)
        if rival is None:
            continue
        swapped = _swapped(structure, chosen, rival)
        better = []
        for (name, part), own in zip(parts, refits, strict=True):
            alternative = _refit(swapped, _warm_fit(swapped, comparison.final, rival), part)
            if alternative.converged and alternative.cost < own.cost:
                better.append(name)
        if better:
            chosen_label, rival_label = chosen.candidate.label, rival.candidate.label
            whole = "the whole series" if len(comparison.series.folds()) > 1 else "the whole record"
            out.append({"chosen": chosen_label, "rival": rival_label, "rival_better_on": better,
                        "sentence": f"{_term_name(rival)} on {', '.join(better)}, "
                        f"{_term_name(chosen)} on {whole}: the data do not tell them apart"})
    return out


def _rival(round_: Sequence[Scored], chosen: Scored) -> Scored | None:
    term = chosen.candidate.term
    if term.effect not in AMPLITUDE_EFFECTS:
        return None
    return next((s for s in round_ if s is not chosen and s.candidate.term.target == term.target
                 and s.candidate.term.effect in AMPLITUDE_EFFECTS
                 and not s.held_out.diverged), None)


def _swapped(structure: Structure, chosen: Scored, rival: Scored) -> Structure:
    """``structure`` with the chosen term replaced by the rival (and the rival's companions)."""
    kept = Structure(structure.series, structure.names,
                     tuple(t for t in structure.terms if t != chosen.candidate.term),
                     structure.inputs)
    return extend(kept, rival.candidate)


def _warm_fit(swapped: Structure, final: Fit, rival: Scored) -> Fit:
    """A stand-in whole fit for :func:`_refit`'s start: the final values, the rival's
    coefficient as its round fitted it."""
    labels, old = swapped.labels(), final.structure.labels()
    theta = swapped.start()
    rival_values = rival.fit.values()
    for k, label in enumerate(labels):
        if label in old:
            theta[k] = final.theta[old.index(label)]
        elif label in rival_values:
            theta[k] = rival_values[label]
    return replace(final, structure=swapped, theta=theta)


def _term_name(scored: Scored) -> str:
    term = scored.candidate.term
    form = {"quadratic_damping": "quadratic damping", "nonlinear_damping": "cubic damping",
            "nonlinear_restoring": "cubic restoring"}.get(term.effect, term.effect)
    return f"{form} on {term.target}"


def widen_findings(findings: Sequence[Finding], spread: dict[str, Any]) -> None:
    """Give each finding's coefficients the reported uncertainty (the larger of the statistical
    std and the between-record spread) with the spread beside it (``between_records``), and
    its confidence recomputed from the wider uncertainty."""
    table = spread["coefficients"]
    for finding in findings:
        for key, std in list(finding.std.items()):
            entry = table.get(_finding_label(finding, key))
            if entry is None:
                continue
            finding.std[key] = entry["uncertainty"]
            finding.between_records[key] = {
                "spread": entry["spread"], "per_record": entry["per_record"],
                "statistical_std": std, "records": spread["records"], "method": spread["method"]}
            if key in ("b", "c"):
                value = max(abs(float(finding.parameters[key])), 1e-300)
                before = max(0.0, 1.0 - std / value)
                tie = finding.confidence / before if before > 0 else 1.0  # 0.5 when tied
                finding.confidence = round(max(0.0, 1.0 - entry["uncertainty"] / value) * tie, 4)


def _finding_label(finding: Finding, key: str) -> str:
    """The unknown's label of a finding's parameter ``key`` (``b``, ``c`` or
    ``with_EFFECT``, a companion on the same state and source)."""
    if key.startswith("with_"):
        source = finding.parameters.get("source")
        return term_label(basis(key[5:], finding.target, **({"source": source} if source else {})))
    return term_label(Effect(finding.effect, finding.target, finding.parameters))


# -- amplitude classes ----------------------------------------------------------------------------
def manoeuvre_amplitude(series: Series, run_index: int) -> dict[str, float]:
    """A record's manoeuvre, model units: ``input`` the largest |input - its trim| over the
    moving inputs and ``check`` the median |heading change| at the input's reversals (a
    zigzag's heading check), or ``initial`` a free decay's largest deviation from its end
    value in the first tenth of the record."""
    run, model = series.runs[run_index], series.model
    moving = np.flatnonzero(series.moving)
    if moving.size:
        u = run.u[:, moving] - model.u0[moving]
        out = {"input": float(np.max(np.abs(u)))}
        heading = _heading_channel(series)
        main = u[:, int(np.argmax(np.max(np.abs(u), axis=0)))]
        executes = _executes(main)
        if heading is not None and executes:
            psi = run.y[:, heading]
            out["check"] = float(np.median(np.abs(psi[executes] - psi[0])))
        return out
    y = run.y / series.scale
    tail = np.median(y[-max(len(y) // 10, 1):], axis=0)
    first = y[: max(len(y) // 10, 2)] - tail
    j = int(np.argmax(np.max(np.abs(first), axis=0)))
    return {"initial": float(np.max(np.abs(first[:, j])) * series.scale[j])}


def _executes(u: FloatArray) -> list[int]:
    """The samples where the input leaves each held extreme to reverse (a zigzag's executes):
    per stretch between sign changes, the last sample within 5 % of the stretch's largest
    |input| (its zero crossing comes later by the rudder's travel, when the heading has run
    past the check)."""
    flips = np.flatnonzero(np.diff(np.signbit(u))) + 1
    out = []
    for a, b in zip(np.r_[0, flips[:-1]], flips, strict=True):
        stretch = np.abs(u[a:b])
        out.append(int(a + np.flatnonzero(stretch >= 0.95 * stretch.max())[-1]))
    return out


def _heading_channel(series: Series) -> int | None:
    """The measured displacement channel an input turns (a heading), or None."""
    model = series.model
    for i in sorted(displacements(model)):
        name = model.state_names[i]
        if name in series.channels:
            return series.channels.index(name)
    return None


def amplitude_classes(series: Series,
                      tolerance: float = CLASS_TOLERANCE) -> list[dict[str, Any]]:
    """The records grouped by manoeuvre amplitude (:func:`manoeuvre_amplitude`): each class's
    ``records`` (indices), their ``amplitude`` (its members' mean per measure) and a ``label``
    (angles in deg: ``"20/5"`` amplitude/check, ``"12°"`` a decay's start)."""
    amplitudes = [manoeuvre_amplitude(series, k) for k in range(len(series.runs))]
    classes: list[list[int]] = []
    for k, amplitude in enumerate(amplitudes):
        home = next((c for c in classes if _agree(amplitudes[c[0]], amplitude, tolerance)), None)
        if home is None:
            classes.append([k])
        else:
            home.append(k)
    out = []
    for members in classes:
        mean = {key: float(np.mean([amplitudes[k][key] for k in members]))
                for key in amplitudes[members[0]]}
        out.append({"records": members, "amplitude": mean, "label": _class_label(series, mean)})
    return out


def _agree(a: dict[str, float], b: dict[str, float], tolerance: float) -> bool:
    return a.keys() == b.keys() and all(
        abs(a[k] - b[k]) <= tolerance * max(abs(a[k]), abs(b[k]), 1e-12) for k in a)


def _class_label(series: Series, amplitude: dict[str, float]) -> str:
    model = series.model
    angle = [u.startswith("rad") for u in model.input_units]
    if "input" in amplitude:
        moving = np.flatnonzero(series.moving)
        degrees = all(angle[j] for j in moving)
        scale = math.degrees(1.0) if degrees else 1.0
        text = f"{amplitude['input'] * scale:.2g}"
        if "check" in amplitude:
            text += f"/{math.degrees(amplitude['check']):.2g}"
        return text
    return f"{math.degrees(amplitude['initial']):.3g}°"


# -- across classes -------------------------------------------------------------------------------
def richer_models(series: Series) -> tuple[str, ...]:
    """The richer host models the series' model declares (``richer_models`` ClassVar, e.g.
    ``("mmg",)`` on ``nomoto``): names a caller may validate with :func:`across_classes`."""
    return tuple(series.model.richer_models)


def richer_series(series: Series) -> list[tuple[Series, tuple[str, ...]]]:
    """The series re-read by each richer host its model declares (:func:`richer_models`), with
    the parameters to calibrate on the training classes (the richer model's
    ``calibration_candidates``): the shared inputs as recorded, the others held at the richer
    model's nominal input (e.g. the propeller speed of a zigzag), the shared channels measured."""
    out = []
    for name in richer_models(series):
        model = get_model(name)
        shared = [c for c in series.channels if c in model.output_names]
        records = []
        for run in series.runs:
            u = np.tile(model.u0, (len(run.time), 1))
            for j, input_name in enumerate(series.model.input_names):
                if input_name in model.input_names:
                    u[:, model.input_names.index(input_name)] = run.u[:, j]
            measured = {c: run.y[:, series.channels.index(c)] for c in shared}
            records.append(Recording.from_arrays(name, run.time, u, measured,
                                                 meta={"name": run.name}))
        names = tuple(model.calibration_candidates)
        out.append((Series.from_recordings(records, model, names), names))
    return out


def across_classes(comparison: Comparison, tolerance: float = CLASS_TOLERANCE,
                   richer: Sequence[tuple[Series, Sequence[str]]] | None = None
                   ) -> dict[str, Any]:
    """Leave one amplitude class out (module doc), for the nominal-calibrated and the corrected
    model and each ``richer`` host (the same records, in the same order, as a series of the
    richer model, with the parameters to calibrate on the training classes; None: those the
    model declares, :func:`richer_series`); empty when the series spans fewer than two classes
    or nothing was corrected."""
    series = comparison.series
    if any(run.record is not None for run in series.runs):
        return {}  # windows of records, not manoeuvres: no amplitude class to read
    classes = amplitude_classes(series, tolerance)
    if len(classes) < 2 or not comparison.accepted:
        return {}
    nominal, final = comparison.nominal, comparison.final
    richer = richer_series(series) if richer is None else richer
    hosts = [Structure(host, tuple(names)) for host, names in richer]
    channel = _headline(series)
    rows = []
    for c in classes:
        held = c["records"]
        row = {"class": c["label"], "records": [series.runs[k].name for k in held],
               "fitted_on": [o["label"] for o in classes if o is not c],
               "nominal": class_error(nominal.structure, nominal.theta, held),
               "corrected": class_error(final.structure, final.theta, held)}
        if hosts:
            row["richer"] = {h.series.model.name: class_error(h, h.start(), held)
                             for h in hosts}
        rows.append(row)
    rerun = all("rerun_rmse" in row[m] for row in rows for m in ("nominal", "corrected"))
    for row in rows:
        before, after = (_judged(row[m], rerun, channel) for m in ("nominal", "corrected"))
        row["cut"] = 1 - math.sqrt(after / max(before, 1e-300)) if math.isfinite(after) \
            else -math.inf
        row["worse"] = not after <= (1 + WORSE) * before
    worse = [row["class"] for row in rows if row["worse"]]
    how = ("re-run as its zig-zag (rudder reversed where the predicted heading reaches the "
           "record's check)" if rerun else "free-simulated (recorded inputs replayed, only its "
           "initial states fitted)")
    out = {"method": f"leave one amplitude class out: each class {how} by the models fitted "
                     "on the other classes", "judged": "re-run" if rerun else "replayed",
           "tolerance": tolerance, "channel": channel, "classes": rows, "worse": worse,
           "richer_models": list(richer_models(series)),
           "verdict": ("the host model is too simple for these records: the correction "
                       "fitted on other amplitudes makes " + ", ".join(worse) + " worse")
           if worse else ""}
    if hosts:
        out["richer"] = _richer_verdict(rows, channel, rerun)
    return out


def _judged(entry: dict[str, Any], rerun: bool, channel: str) -> float:
    """The mean square a class is judged on: the re-run's headline channel (squared RMS), or
    the replay's mean square over the channels in signal scales."""
    if not rerun:
        return entry["mean_square"]
    value = entry["rerun_rmse"].get(channel, math.inf)
    return value**2 if math.isfinite(value) else math.inf


def _richer_verdict(rows: Sequence[dict[str, Any]], channel: str,
                    rerun: bool = False) -> dict[str, str]:
    """Per richer host: whether it explains the held-out classes (every class's RMS in the
    headline channel at most the nominal model's, by :data:`WORSE`, and their mean below),
    re-run as the manoeuvre when the classes are judged so and the richer host can be."""
    out = {}
    for name in rows[0]["richer"]:
        again = rerun and all("rerun_rmse" in row["richer"][name] for row in rows)
        key = "rerun_rmse" if again else "rmse"
        ratios = [row["richer"][name][key].get(channel, math.inf)
                  / max(row["nominal"][key][channel], 1e-300) for row in rows]
        good = all(r <= 1 + WORSE for r in ratios) and float(np.mean(ratios)) < 1
        out[name] = (f"{name} explains the held-out classes ({channel} RMS "
                     f"{float(np.mean(ratios)):.2f}x the nominal model's on average)" if good else
                     f"{name} does not explain them either ({channel} RMS "
                     + ", ".join(f"{r:.2f}x" for r in ratios) + " the nominal model's)")
    return out


def class_error(structure: Structure, theta: FloatArray, held: Sequence[int]) -> dict[str, Any]:
    """``structure`` fitted (from ``theta``) on every record but ``held``, then free-simulating
    each held record (its own initial states fitted): RMS per channel (model units) and the
    mean square in signal scales (runs alike); for zig-zags also ``rerun_rmse``, each held
    record re-run as its zig-zag (:func:`.validation.rerun_from_fit`), rad."""
    series = structure.series
    own = np.concatenate([_states_of(structure, r) for r in held]).astype(int)
    rows: list[Any] = all_rows(series)
    for r in held:
        rows[r] = None
    trained = fit(structure, rows, theta, fixed=own).theta
    errors = []
    for r in held:
        alone: list[Any] = [None] * len(series.runs)
        alone[r] = np.ones(len(series.runs[r].time), dtype=bool)
        rest = np.setdiff1d(np.arange(structure.size), _states_of(structure, r))
        fitted = fit(structure, alone, trained, fixed=rest).theta
        errors.append((structure.simulate(fitted, r)[0] - series.runs[r].y) / series.scale)
    diverged = any(not np.all(np.abs(e) <= 1e2) for e in errors)
    errors = [np.clip(np.nan_to_num(e, nan=1e2), -1e2, 1e2) for e in errors]
    stacked = np.concatenate(errors)
    rmse = {c: float(np.sqrt(np.mean(stacked[:, j] ** 2)) * series.scale[j])
            for j, c in enumerate(series.channels)}
    out = {"rmse": rmse, "diverged": diverged,
           "mean_square": math.inf if diverged else float(np.mean([np.mean(e**2)
                                                                    for e in errors]))}
    # zig-zags are also judged as they are run: steered closed loop, a course-unstable ship
    # does not drift from a small error as it does replayed open loop
    rerun = [rerun_from_fit(structure, trained, r) for r in held]
    if all(e is not None for e in rerun):
        out["rerun_rmse"] = {c: float(np.sqrt(np.mean([e[c] ** 2 for e in rerun])))
                             for c in rerun[0]}
    return out


def _states_of(structure: Structure, run: int) -> NDArray[np.int_]:
    """Indices of run ``run``'s initial states among the structure's unknowns."""
    per_state = len(structure.free_states)
    first = len(structure.names) + len(structure.terms)
    return np.arange(first + run * per_state, first + (run + 1) * per_state)


def _headline(series: Series) -> str:
    """The channel the sentences quote: the heading (a displacement) when measured."""
    k = _heading_channel(series)
    return series.channels[0 if k is None else k]
