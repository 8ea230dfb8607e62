"""The diagnosis of model tests (decays, zigzags, lab runs, a series of them) in free simulation.

1. Resample the recordings to the model's bandwidth (:class:`.output_error.Series`).
2. Read free decays as a naval architect does (:mod:`.modes`): natural frequency and damping;
   a model whose modes are elsewhere is the wrong model unless ``calibrate`` names a parameter
   that moves them, and the calibration starts from the record's values.
3. Whole records the model cannot follow from a fitted start (a craft spinning for 30 s) are
   cut into the longest windows it follows, each with its own start (multiple shooting), and
   the model's parameters the failing channels are most sensitive to are calibrated with the
   named ones (:mod:`.self_calibration`): the advice to calibrate, followed by the tool itself.
4. Calibrate the named parameters by output error, with standard errors, correlations and a
   verdict per parameter (never a start value passed off as a fit).
5. Compare nested models on held-out data (:mod:`.comparison`) and report the accepted terms,
   each in its equation's standard form, the competitors that explain the data equally, and
   what is left unexplained.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from marine_envs.models import VehicleModel
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording

from .comparison import MAX_CORRELATION, Comparison, ComparisonConfig, HeldOut, Scored, compare
from .explain import describe, separating_test
from .modes import check_modes, free_decays, mode_start
from .output_error import Fit, Series, term_label
from .ranges import (
    NONPHYSICAL,
    equivalent_offset,
    fitted_range,
    standard_form,
    state_histories,
)
from .result import Diagnosis, Finding
from .self_calibration import nominal_fit, self_calibration
from .spread import across_classes, between_records, widen_findings

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]
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
    whole = nominal_fit(series, calibrate, start)
    own = self_calibration(whole, say) if whole.cost > MAX_UNFOLLOWED else None
    if own is not None:  # whole records are beyond the model's horizon: windows, calibrated
        series, calibrate, start = own.series, own.names, own.start
    else:  # the comparison's nominal fit starts where this one ended
        start = whole.values()
    say(f"free simulation of {len(series.runs)} recording(s) at {series.dt:.3g} s steps: "
        f"calibrating {', '.join(calibrate) or 'the initial states'} and comparing nested "
        "models on held-out data (seconds; minutes where a recorded disturbance is an input)...")
    begin(FREE_STAGES[1], 1, len(FREE_STAGES))
    comparison = compare(series, calibrate, start, config)
    if own is not None:
        check = {**(check or {}), "self_calibration": own.report(
            calibration_quality(comparison.nominal, own.names)["parameters"])}
    if comparison.final_held_out.mean_square > MAX_UNFOLLOWED:
        share = math.sqrt(comparison.final_held_out.mean_square)
        advice = "; a record in a seaway is judged with --method innovations" \
            if len(series.runs) == 1 else ""
        refusal = Diagnosis(vehicle.name, None, (
            f"free simulation cannot follow these records (held-out error {share:.0%} of the "
            "signal, with every candidate tried): the model's parameters are far off "
            "(calibrate them) or the vehicle is driven by something the model is not given "
            f"(waves, wind, a tether){advice}"), model_check=check or {},
            comparison=comparison)
        if own is not None:  # what the tool calibrated by itself is reported, refused or not
            refusal.calibration = _values(comparison.nominal, calibrate)
            refusal.calibration_quality = calibration_quality(comparison.nominal, calibrate)
        return refusal
    return with_honest_names(_diagnosis(comparison, calibrate, check),
                             measured_inputs(recordings, vehicle))


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


# -- what the findings may claim: ranges, signs, offsets, measured inputs --------------------------
#: An input in words, where the model's name for it is a symbol.
INPUT_WORDS = {"delta": "rudder"}


def measured_inputs(recordings: Sequence[Recording], model: VehicleModel) -> tuple[str, ...]:
    """The model inputs every record measured rather than commanded: an actuator position
    sensor (``<input>_applied``, which then drives the model) or the recording's
    ``meta["measured_inputs"]`` (a log of the rudder angle itself, as HSVA's zigzags)."""
    return tuple(name for name in model.input_names
                 if all(name in r.actuator_names or name in r.meta.get("measured_inputs", ())
                        for r in recordings))


def with_honest_names(diagnosis: Diagnosis, measured: Sequence[str] = ()) -> Diagnosis:
    """``diagnosis`` with each finding's fitted range, a constant force the model's offset
    parameter explains named as that offset, an actuator effect on a measured input named as
    standing in for missing dynamics, and the candidates refused as non-physical."""
    comparison: Comparison | None = diagnosis.comparison
    if comparison is None:
        return diagnosis
    final = comparison.final
    states = state_histories(final) if comparison.accepted else []
    for finding, scored in zip(diagnosis.findings, comparison.accepted, strict=True):
        term = scored.candidate.term
        finding.fitted_range = fitted_range(final, term, states)
        if term.effect == "current":
            _name_offset(finding, final)
        elif term.kind == "input" and term.target in measured:
            _name_standing_in(finding, final)
    diagnosis.non_physical = _non_physical(comparison)
    return diagnosis


def _name_offset(finding: Finding, final: Fit) -> None:
    """A constant force that an offset parameter of the model explains exactly, named as it
    (with the parameter's value) instead of a current."""
    model = final.structure.series.model
    values = final.values()
    offset = equivalent_offset(model, finding.as_effect(), float(finding.parameters["b"]),
                               float(finding.std.get("b", math.nan)),
                               {n: values[n] for n in final.structure.names})
    if offset is None:
        return
    unit = model.input_units[model.input_names.index(offset.input)] if offset.input else ""
    factor, shown = (180 / math.pi, "deg") if unit == "rad" else (1.0, unit)
    value = f"{offset.value * factor:+.2g} ± {offset.std * factor:.2g} {shown}".rstrip()
    nominal = f"{float(getattr(model.params, offset.parameter)) * factor:g} {shown}".rstrip()
    unit_rate = model.state_units[model.state_names.index(finding.target)]
    rate = f"{finding.parameters['b']:+.3g} " + (f"{unit_rate}²" if unit_rate.endswith("/s")
                                                 else f"{unit_rate}/s")
    word = INPUT_WORDS.get(offset.input, offset.input) if offset.input else ""
    name = f"{word} offset" if word else f"{offset.parameter} offset"
    finding.named_as = {"as": name, "parameter": offset.parameter,
                        "value": offset.value, "std": offset.std, "unit": unit}
    check = f", and check the {word}'s zero (it may differ between runs)" if word else ""
    finding.explanation = (
        f"a {name} of {value} (the model's own {offset.parameter}, left at {nominal}), not a "
        f"current: the constant {rate} in {finding.target}'s equation is exactly what that "
        f"offset adds; calibrate {offset.parameter} with the other parameters{check}; it "
        f"removes {finding.improvement:.0%} of the held-out free-simulation error beyond "
        "sensor noise.")


def _name_standing_in(finding: Finding, final: Fit) -> None:
    """An actuator effect on a measured input: the measured input cannot lag, rate-limit or
    saturate behind itself, so the effect stands in for dynamics the host model lacks."""
    model = final.structure.series.model
    name, p = finding.target, finding.parameters
    word = INPUT_WORDS.get(name, name)
    what = {"input_delay": f"a {p.get('tau', 0):.2g}-s {word} delay",
            "input_rate_limit": f"a {word} rate limit of {p.get('rate', 0):.3g} per second",
            "input_saturation": f"a {word} saturation at ±{p.get('limit', 0):.3g}"}.get(
        finding.effect, f"{finding.effect} on {name}")
    j = model.input_names.index(name)
    driven = [s for i, s in enumerate(model.state_names) if model.linearize()[1][i, j] != 0]
    finding.named_as = {"as": "missing dynamics", "input": name, "measured": True}
    finding.explanation = (
        f"{what}: the {word} is measured and cannot {_verb(finding.effect)} itself; this stands "
        f"in for dynamics between {name} and {', '.join(driven) or 'the motion'} that the host "
        f"model `{model.name}` lacks (a second-order or richer model), not an actuator effect; "
        f"it removes {finding.improvement:.0%} of the held-out free-simulation error beyond "
        "sensor noise.")


def _verb(effect: str) -> str:
    return {"input_delay": "lag", "input_rate_limit": "be slower than",
            "input_saturation": "be clipped against"}.get(effect, "differ from")


def _non_physical(comparison: Comparison) -> list[dict[str, Any]]:
    """Per round, the candidates refused because their sign makes the motion less stable than
    the linear model over the recorded range, with the reason and their held-out share."""
    out = []
    befores = [comparison.nominal_held_out] + [s.held_out for s in comparison.accepted]
    for k, round_ in enumerate(comparison.rounds):
        for scored in round_:
            reason = comparison.refusal(scored, befores[k]) or ""
            if reason.startswith(NONPHYSICAL):
                share = comparison.improvement(befores[k], scored.held_out)
                out.append({"candidate": scored.candidate.label, "round": k + 1,
                            "reason": reason,
                            "improvement": "diverged" if share is None else round(share, 4)})
    return out
