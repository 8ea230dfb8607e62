"""The diagnosis of model tests (decays, zigzags, lab runs, a series of them) in free simulation.

1. Resample the recordings to the model's bandwidth (:class:`.output_error.Series`).
2. Read free decays as a naval architect does (:mod:`.modes`): natural frequency and damping;
   a model whose modes are elsewhere is the wrong model unless ``calibrate`` names a parameter
   that moves them, and the calibration starts from the record's values.
3. Calibrate the named parameters by output error, with standard errors, correlations and a
   verdict per parameter (never a start value passed off as a fit).
4. Compare nested models on held-out data (:mod:`.comparison`) and report the accepted terms,
   each in its equation's standard form, the competitors that explain the data equally, and
   what is left unexplained.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from marine_envs.models import VehicleModel
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording

from .comparison import MAX_CORRELATION, Comparison, ComparisonConfig, HeldOut, Scored, compare
from .explain import describe, separating_test
from .modes import check_modes, free_decays, mode_start
from .output_error import Fit, Series, term_label
from .result import Diagnosis, Finding
from .spread import across_classes, between_records, widen_findings

#: A parameter whose standard deviation exceeds this share of its value is not identified.
MAX_RELATIVE_STD = 0.5
#: The stages of a model test, as :func:`diagnose_series` reports them to ``stage``.
FREE_STAGES = ("resampling", "calibrating and comparing")
#: A held-out mean square error beyond this share of the signal's variance: free simulation
#: does not follow the records at all (they are driven by what the model is not given).
MAX_UNFOLLOWED = 0.5


def diagnose_series(recordings: Sequence[Recording], vehicle: VehicleModel,
                    calibrate: Sequence[str] = (), config: ComparisonConfig | None = None,
                    log: Callable[[str], None] | None = None,
                    stage: Callable[[str, int, int], None] | None = None) -> Diagnosis:
    """Diagnose model tests in free simulation (module doc); one parameter set for all.

    :param stage: called at the start of each of :data:`FREE_STAGES` with its name, index and
        their number.
    """
    config = config or ComparisonConfig()
    say = log or (lambda _line: None)
    begin = stage or (lambda _name, _k, _n: None)
    begin(FREE_STAGES[0], 0, len(FREE_STAGES))
    series = Series.from_recordings(recordings, vehicle, calibrate)
    problem = _too_little(series, calibrate)
    if problem:
        return Diagnosis(vehicle.name, None, problem)
    # the first free decay of the series: its mode checks the model and starts the calibration
    decay = next((d for run in series.runs for d in free_decays(
        run.time, run.u, run.y, run.noise, series.channels).values()), None)
    check = check_modes(vehicle, series.channels, decay, calibrate) if decay else None
    start = mode_start(vehicle, series.channels, decay, calibrate) if decay else None
    if check and not check["matches"] and not start:
        return Diagnosis(vehicle.name, None, str(check["advice"]), model_check=check)
    say(f"free simulation of {len(series.runs)} recording(s) at {series.dt:.3g} s steps: "
        f"calibrating {', '.join(calibrate) or 'the initial states'} and comparing nested "
        "models on held-out data (seconds for a linear model, minutes for a nonlinear one)...")
    begin(FREE_STAGES[1], 1, len(FREE_STAGES))
    comparison = compare(series, calibrate, start, config)
    if comparison.final_held_out.mean_square > MAX_UNFOLLOWED:
        share = math.sqrt(comparison.final_held_out.mean_square)
        advice = "; a record in a seaway is judged with --method innovations" \
            if len(series.runs) == 1 else ""
        return Diagnosis(vehicle.name, None, (
            f"free simulation cannot follow these records (held-out error {share:.0%} of the "
            "signal, with every candidate tried): the model's parameters are far off "
            "(calibrate them) or the vehicle is driven by something the model is not given "
            f"(waves, wind, a tether){advice}"), model_check=check or {},
            comparison=comparison)
    return _diagnosis(comparison, calibrate, check)


def _too_little(series: Series, calibrate: Sequence[str]) -> str:
    """Why the series holds too little to judge, or ``""``: no channel moves beyond its noise,
    or fewer independent samples than ten per unknown."""
    moving = [np.std(r.y, axis=0) > 5 * r.noise for r in series.runs]
    if not np.any(moving):
        return ("no excitation: no measured channel moves beyond its sensor noise; excite the "
                "vehicle (inputs, a release from an offset) and record again")
    samples = sum(len(r.time) for r in series.runs)
    unknowns = len(calibrate) + 3 + len(series.runs) * int(series.excited().sum())
    if samples < 10 * unknowns:
        return (f"too short to say anything: {samples} samples at the model's bandwidth for "
                f"{unknowns} unknowns; record longer or add recordings to the series")
    return ""


# -- the answer -----------------------------------------------------------------------------------
def _diagnosis(comparison: Comparison, calibrate: Sequence[str],
               check: dict[str, Any] | None) -> Diagnosis:
    series = comparison.series
    nominal, final = comparison.nominal_held_out, comparison.final_held_out
    findings, previous = [], nominal
    for k, scored in enumerate(comparison.accepted):
        gain = comparison.improvement(nominal, scored.held_out) or 0.0
        before = comparison.improvement(nominal, previous) or 0.0 if k else 0.0
        findings.append(_finding(scored, comparison, gain - before))
        previous = scored.held_out
    explained = comparison.explained()
    diagnosis = Diagnosis(series.model.name, bool(findings) or not explained,
                          findings=findings, calibration=_values(comparison.nominal, calibrate),
                          model_check=check or {}, comparison=comparison)
    diagnosis.calibration_quality = calibration_quality(comparison.nominal, calibrate)
    if findings and calibrate:  # the same parameters refitted with the findings
        diagnosis.calibration_quality["with_findings"] = calibration_quality(
            comparison.final, calibrate)["parameters"]
    diagnosis.channels = _channels(nominal)
    improvement = comparison.improvement(nominal, final)
    diagnosis.fit = {
        "method": "free simulation",
        "before": {"rmse": nominal.rmse}, "after": {"rmse": final.rmse},
        "improvement": "diverged" if improvement is None else round(improvement, 4),
        "validation": comparison.validation(),
        "noise_rmse": {c: float(np.sqrt(np.mean([r.noise[j] ** 2 for r in series.runs])))
                       for j, c in enumerate(series.channels)},
        "terms": [{"effect": f.effect, "target": f.target, "improvement": f.improvement}
                  for f in findings],
    }
    if not explained:
        diagnosis.unexplained = _unexplained(comparison)
        diagnosis.not_kept = _not_kept(comparison)
    diagnosis.alternatives = _alternatives(comparison)
    with_spread(diagnosis, comparison, calibrate)
    return diagnosis


def with_spread(diagnosis: Diagnosis, comparison: Comparison, calibrate: Sequence[str]) -> None:
    """The coefficients' spread between records (or pieces of one) beside their statistical
    std, the uncertainty reported being the larger; and, when the series spans several
    amplitude classes, the leave-one-class-out validation (:mod:`.spread`)."""
    if not (comparison.accepted or calibrate):
        return
    spread = between_records(comparison)
    widen_findings(diagnosis.findings, spread)
    quality = diagnosis.calibration_quality
    table = quality.get("with_findings") or quality.get("parameters", {})
    for name, entry in table.items():
        found = spread["coefficients"].get(name)
        if found:
            entry["between_records"] = {k: found[k] for k in ("spread", "per_record")} | {
                "records": spread["records"], "method": spread["method"]}
            entry["uncertainty"] = found["uncertainty"]
            relative = found["spread"] / max(abs(entry["value"]), 1e-300)
            if entry["status"] == "identified" and relative > MAX_RELATIVE_STD:
                entry["status"] = (f"poorly identified (it moves by {relative:.0%} of its value "
                                   "between records)")
    diagnosis.fit["between_records"] = spread
    diagnosis.across_classes = across_classes(comparison)


def _values(fit: Fit, names: Sequence[str]) -> dict[str, float]:
    values = fit.values()
    return {n: values[n] for n in names}


def calibration_quality(fit: Fit, names: Sequence[str]) -> dict[str, Any]:
    """Per calibrated parameter: value, std and a verdict; the strong correlations; whether
    the solver converged."""
    labels = fit.structure.labels()
    out: dict[str, Any] = {"converged": fit.converged, "parameters": {}, "correlations": []}
    for name in names:
        k = labels.index(name)
        value, std = float(fit.theta[k]), float(fit.std[k])
        column = fit.jacobian[:, k] if k < fit.jacobian.shape[1] else np.zeros(1)
        if not math.isfinite(std) and not np.any(column):
            status = "not identifiable: the measured channels do not depend on it"
        elif not math.isfinite(std):
            status = ("not identifiable: the records hold it only in a combination with other "
                      "unknowns")
        elif std > MAX_RELATIVE_STD * abs(value):
            status = f"poorly identified (std {std / max(abs(value), 1e-300):.0%} of the value)"
        else:
            status = "identified"
        out["parameters"][name] = {"value": value, "std": std, "status": status}
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            rho = float(fit.correlation[labels.index(a), labels.index(b)])
            if abs(rho) > MAX_CORRELATION:
                out["correlations"].append({"parameters": [a, b], "correlation": rho,
                                            "status": "the records cannot tell them apart"})
    return out


def _finding(scored: Scored, comparison: Comparison, share: float) -> Finding:
    """The term as the final model has it (refitted with every accepted term)."""
    fit, term = comparison.final, scored.candidate.term
    if term.kind == "input":  # a grid member: its value is the grid's, to half a step
        sentence = f"{describe(term)}; it removes {share:.0%} of the held-out " \
                   "free-simulation error beyond sensor noise"
        return Finding(term.effect, term.target, dict(term.parameters), {},
                       1.0 if not _tied(comparison, scored) else 0.5, round(share, 4),
                       sentence + ".")
    values, labels = fit.values(), fit.structure.labels()
    key = "b" if "b" in term.parameters else "c"
    text = {k: v for k, v in term.parameters.items() if isinstance(v, str)}
    k = labels.index(term_label(term))
    parameters: dict[str, Any] = {**text, key: values[term_label(term)]}
    std = {key: float(fit.std[k])}
    for companion in scored.candidate.companions:
        label = term_label(companion)
        parameters[f"with_{companion.effect}"] = values[label]
        std[f"with_{companion.effect}"] = float(fit.std[labels.index(label)])
    effect = Effect(term.effect, term.target, parameters)
    relative = std[key] / max(abs(parameters[key]), 1e-300)
    confidence = max(0.0, 1.0 - relative) * (0.5 if _tied(comparison, scored) else 1.0)
    sentence = f"{describe(effect)}; it removes {share:.0%} of the held-out free-simulation " \
               "error beyond sensor noise"
    finding = Finding(term.effect, term.target, parameters, std, round(confidence, 4),
                      round(share, 4), sentence + ".")
    finding.standard_form = standard_form(fit, term.target)
    return finding


def standard_form(fit: Fit, target: str) -> dict[str, float]:
    """The fitted equation of ``target`` in its field's coefficients: ``target' = -B1 x - B2
    x|x| - B3 x^3 - C1 q - C3 q^3 + G_u u + ...`` (x the target, q its restoring source, u each
    input that moves in the records), per unit inertia, at the fitted parameters (B: damping,
    C: restoring, G: input gain; Nomoto's ``T r' + r = K delta`` has B1 = 1/T, G = K/T, which
    stay defined when a nonlinear damping takes over B1 and K, T do not)."""
    structure, values = fit.structure, fit.values()
    model = structure.series.model
    model = model.with_params(**{n: values[n] for n in structure.names})
    A, B, _ = model.linearize()
    i = model.state_names.index(target)
    form = {"B1": -float(A[i, i])}
    for term in structure.terms:
        if term.target != target:
            continue
        c = values[term_label(term)]
        key = {"linear_damping": "B1", "quadratic_damping": "B2", "nonlinear_damping": "B3",
               "coupling": "C1", "nonlinear_restoring": "C3"}.get(term.effect)
        if key:
            form[key] = form.get(key, 0.0) - c
        source = term.parameters.get("source")
        if source and "C1" not in form:
            form["C1"] = -float(A[i, model.state_names.index(source)])
    form |= {f"G_{u}": float(B[i, j]) for j, u in enumerate(model.input_names)
             if structure.series.moving[j] and B[i, j] != 0}
    return {k: float(f"{v:.6g}") for k, v in form.items()}


def _equal(comparison: Comparison, a: Scored, b: Scored) -> bool:
    """Held-out errors within the configured tie of each other."""
    best = min(a.held_out.mean_square, b.held_out.mean_square)
    return abs(a.held_out.mean_square - b.held_out.mean_square) < comparison.config.tie * best


def _tied(comparison: Comparison, scored: Scored) -> bool:
    """Another candidate of its round explains the held-out data as well."""
    return any(_equal(comparison, scored, other) for round_ in comparison.rounds
               if any(s is scored for s in round_) for other in round_ if other is not scored)


def _not_kept(comparison: Comparison) -> list[dict[str, Any]]:
    """The last round's candidates, each with its share of the remaining held-out error and
    why it was not kept."""
    before = comparison.final_held_out
    out = []
    for scored, reason in comparison.not_kept():
        share = comparison.improvement(before, scored.held_out)
        out.append({"candidate": scored.candidate.label, "reason": reason,
                    "improvement": "diverged" if share is None else round(share, 4)})
    return out


def _alternatives(comparison: Comparison) -> list[dict[str, Any]]:
    """Per accepted term, the competitors its round could not tell from it, and a test that
    would."""
    out = []
    for round_ in comparison.rounds:
        chosen = next((s for s in round_ if any(s is a for a in comparison.accepted)), None)
        if chosen is None:
            continue
        out += [{"chosen": chosen.candidate.label, "equally": other.candidate.label,
                 "separate_by": separating_test(chosen.candidate.term, other.candidate.term)}
                for other in round_ if other is not chosen and _equal(comparison, chosen, other)]
    return out


def _channels(nominal: HeldOut) -> list[dict[str, Any]]:
    ranked = sorted(nominal.rmse.items(), key=lambda item: -item[1])
    return [{"name": c, "rmse": round(v, 6)} for c, v in ranked]


def _unexplained(comparison: Comparison) -> dict[str, Any]:
    """What the final model leaves, per channel: RMS held-out error and its share of the
    signal's RMS."""
    series, rmse = comparison.series, comparison.final_held_out.rmse
    model = series.model
    units = dict(zip(model.output_names, model.output_units, strict=True))
    return {c: {"rmse": rmse[c], "unit": units[c],
                "share_of_signal": round(rmse[c] / float(series.scale[j]), 4)}
            for j, c in enumerate(series.channels)}
