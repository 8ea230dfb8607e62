"""The report of a model-test diagnosis (free simulation, :mod:`.free_simulation`).

:func:`~estimators.diagnosis.report.write_report` hands a diagnosis with a ``comparison`` to this
module: its figures (:mod:`.free_simulation_figures`) and the text of ``report.md``: verdict, model
check, calibrated parameters, findings (with each equation's standard form), held-out free
simulation, alternatives, what is left unexplained, the figures and how to read them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .comparison import Comparison
from .free_simulation import standard_form
from .free_simulation_figures import channel_units, display_unit, with_degrees
from .modes import MODE_TOLERANCE, free_decays, model_modes
from .output_error import Fit
from .ranges import span
from .report_format import cell, change, num, parameters
from .result import Diagnosis, Finding

FloatArray = NDArray[np.float64]
#: The terms of the standard form, in order, and what they multiply.
STANDARD_TERMS = (("B1", "{x}"), ("B2", "{x}|{x}|"), ("B3", "{x}³"), ("C1", "{q}"),
                  ("C3", "{q}³"))


# -- Markdown -------------------------------------------------------------------------------------
def markdown(diagnosis: Diagnosis, figures: Sequence[tuple[str, str]] = (),
             recording_name: str = "") -> str:
    """The text of a model-test report; ``figures`` are ``(relative file name, caption)``."""
    comparison: Comparison | None = diagnosis.comparison
    title = recording_name or diagnosis.model
    runs = len(comparison.series.runs) if comparison is not None else 1
    parts = [f"# Mismatch diagnosis: {cell(title)}", "",
             f"Model: `{diagnosis.model}`" + (f" · recording{'s' if runs > 1 else ''}: "
                                              f"`{recording_name}`" if recording_name else "")
             + " · method: free simulation (model test)", "",
             "## Verdict", "", verdict(diagnosis), ""]
    if comparison is None or diagnosis.mismatch is None:
        return "\n".join(parts + _model_check(diagnosis, comparison))
    parts += _model_check(diagnosis, comparison) + _calibration(diagnosis, comparison) \
        + _findings(diagnosis, comparison) + _held_out(diagnosis, comparison) \
        + _alternatives(diagnosis) + spread_lines(diagnosis) + across_classes_lines(diagnosis) \
        + _unexplained(diagnosis, comparison)
    if figures:
        parts += ["## Figures", ""]
        for name, caption in figures:
            parts += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    parts += ["## How to read this", "", how_to_read(comparison), "",
              "The full result is in [`diagnosis.json`](diagnosis.json).", ""]
    return "\n".join(parts)


def verdict(diagnosis: Diagnosis) -> str:
    """One paragraph: mismatch found (and whether something is left), no mismatch, a mismatch
    the catalogue does not explain, or cannot judge (with the reason)."""
    if diagnosis.mismatch is None:
        return f"**Cannot judge.** {diagnosis.reason}"
    left = _left_over(diagnosis)
    if diagnosis.findings:
        names = ", ".join(f"`{f.effect}` on `{f.target}`" for f in diagnosis.findings)
        improvement = diagnosis.fit.get("improvement")
        gain = ("; but the model with them diverges in the held-out free simulation, so their "
                "combined gain cannot be measured" if improvement == "diverged" else
                f"; {'together they remove' if len(diagnosis.findings) > 1 else 'it removes'} "
                f"{_percent(improvement)} of the held-out free-simulation error in excess of "
                "the sensor noise")
        return (f"**Mismatch found:** the model lacks {names}{gain}."
                + (f" **Still unexplained:** {left}." if left else
                   " What is left is within the sensor noise.") + _class_limit(diagnosis))
    if diagnosis.mismatch:
        return ("**Mismatch, unexplained by the catalogue:** the calibrated model does not "
                "simulate the held-out data within the sensor noise" + (f" ({left})" if left
                                                                        else "")
                + ", and no catalogue term removes enough of the difference.")
    return ("**No significant mismatch.** The calibrated nominal model simulates the held-out "
            "data within the sensor noise; no catalogue term is needed."
            + (f" {diagnosis.reason}" if diagnosis.reason else ""))


def _left_over(diagnosis: Diagnosis) -> str:
    """``"RMS x in phi (y % of the signal)"`` per unexplained channel."""
    units = _units(diagnosis)
    return "; ".join(f"RMS {with_degrees(v['rmse'], units.get(c, ''))} in `{c}` "
                     f"({_percent(v['share_of_signal'])} of the signal's RMS)"
                     for c, v in diagnosis.unexplained.items())


def _units(diagnosis: Diagnosis) -> dict[str, str]:
    return channel_units(diagnosis.comparison) if diagnosis.comparison is not None else {}


def _model_check(diagnosis: Diagnosis, comparison: Comparison | None) -> list[str]:
    """The record's mode (natural frequency, damping ratio, period) against the model's."""
    check = diagnosis.model_check
    out = ["## Model check", ""]
    if not check:
        if comparison is None:
            return []
        return out + ["No free decay in the record (an input moves, or fewer than two periods "
                      "rise above the noise): the modes were not checked.", ""]
    record = check["record"]
    channel = _decay_channel(comparison)
    first = ", first recording" if comparison is not None and len(comparison.series.runs) > 1 \
        else ""
    rows = [f"| record{f' (decay of `{channel}`{first})' if channel else ''} | "
            f"{record['omega_n']:.4g} | {record['zeta']:.4g} | {record['period']:.4g} |"]
    for k, mode in enumerate(check.get("model", []), 1):
        rows.append(f"| model as set, mode {k} | {mode['omega_n']:.4g} | {mode['zeta']:.4g} | "
                    f"{_period(mode['omega_n'], mode['zeta'])} |")
    calibrated = _calibrated_modes(diagnosis, comparison)
    for k, (omega, zeta) in enumerate(calibrated, 1):
        rows.append(f"| calibrated model, mode {k} | {omega:.4g} | {zeta:.4g} | "
                    f"{_period(omega, zeta)} |")
    out += ["The record's own mode, read from the extrema of the free decay (period from the "
            "zero crossings, damping from the logarithmic decrement of the first periods), "
            "against the observable modes of the linearised model:", "",
            "| | natural frequency (rad/s) | damping ratio | damped period (s) |",
            "| --- | ---: | ---: | ---: |", *rows, ""]
    if check.get("matches"):
        out.append("The model as set has a mode at the record's natural frequency (within "
                   f"{MODE_TOLERANCE:.0%}).")
    else:
        out.append(f"**The model as set does not match:** {check.get('advice', '')}."
                   + (" The calibration started from the record's mode." if calibrated else ""))
    return out + [""]


def _decay_channel(comparison: Comparison | None) -> str:
    """The channel whose decay the model check read (the first decaying one)."""
    if comparison is None:
        return ""
    series = comparison.series
    for run in series.runs:
        decays = free_decays(run.time, run.u, run.y, run.noise, series.channels)
        if decays:
            return next(iter(decays))
    return ""


def _calibrated_modes(diagnosis: Diagnosis, comparison: Comparison | None
                      ) -> list[tuple[float, float]]:
    """The observable modes of the model with its calibrated parameters (none when nothing was
    calibrated)."""
    if comparison is None or not diagnosis.calibration:
        return []
    model = comparison.series.model.with_params(**diagnosis.calibration)
    return model_modes(model, comparison.series.channels)


def _period(omega: float, zeta: float) -> str:
    return f"{2 * math.pi / (omega * math.sqrt(1 - zeta**2)):.4g}" \
        if 0 < zeta < 1 and omega > 0 else ("∞" if omega == 0 else "– (not oscillatory)")


def _calibration(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """Calibrated parameters: as set, fitted ± std, refitted with the findings, verdict; the
    correlations the records cannot resolve."""
    quality = diagnosis.calibration_quality
    parameters = quality.get("parameters", {})
    if not parameters:
        return []
    refitted = quality.get("with_findings", {})  # the final model's fit of the same names
    with_terms = bool(refitted)
    header = "| parameter | as set | calibrated (± std) |" + (" with the findings (± std) |"
                                                              if with_terms else "") \
        + " status |"
    rows = []
    for name, q in parameters.items():
        row = (f"| {name} | {num(float(getattr(comparison.series.model.params, name)))} | "
               f"{num(q['value'])} ± {num(q['std'])} |")
        status = q["status"]
        if with_terms:
            final = refitted[name]
            row += f" {num(final['value'])} ± {num(final['std'])} |"
            if final["status"] != "identified":
                status += f"; with the findings {final['status']}"
        rows.append(row + f" {cell(status)} |")
    out = ["## Calibrated parameters", "",
           "Fitted by output error (free simulation of "
           + ("every recording" if len(comparison.series.runs) > 1 else "the whole record")
           + "), standard deviations "
           "from the residuals' effective number of independent samples"
           + ("; the last value column is the final model's, refitted with the accepted terms"
              if with_terms else "") + ":", "", header,
           "| --- | ---: | ---: |" + (" ---: |" if with_terms else "") + " --- |", *rows, ""]
    if not quality.get("converged", True):
        out += ["**The solver did not converge:** treat these values with care.", ""]
    correlations = quality.get("correlations", [])
    if correlations:
        out += [f"Correlated: {' and '.join(c['parameters'])} ({c['correlation']:+.3f}): "
                f"{c['status']}." for c in correlations] + [""]
    else:
        out += ["No pair of calibrated parameters is correlated beyond ±0.98: the records "
                "tell them apart.", ""]
    return out


def _findings(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """The findings table and the final model's equations in standard form."""
    out = ["## Findings", ""]
    if not diagnosis.findings:
        return out + ["None: no catalogue term removed enough of the held-out free-simulation "
                      "error.", "", *non_physical(diagnosis)]
    out += ["Terms accepted one at a time, each refitted together with the calibrated "
            "parameters and the terms before it; a row's parameters and standard form are "
            "those of the model at the round its term was accepted.", "",
            "| # | effect | target | parameters (± std) | standard form | confidence | "
            "improvement | explanation |",
            "| ---: | --- | --- | --- | --- | ---: | ---: | --- |"]
    for k, f in enumerate(diagnosis.findings, 1):
        form = ", ".join(f"{key} = {num(value)}" for key, value in f.standard_form.items())
        effect = f.effect + (f" ({f.named_as['as']})" if f.named_as else "")
        out.append(f"| {k} | {effect} | {f.target} | {cell(parameters(f))} | {form} | "
                   f"{f.confidence:.2f} | {_percent(f.improvement)} | "
                   f"{cell(f.explanation)} |")
    out += ["", *fitted_ranges(diagnosis, comparison)]
    out += ["", "Final model, all terms refitted together on all data (per unit inertia):", ""]
    notes = []
    for target in dict.fromkeys(f.target for f in diagnosis.findings):
        equation = _equation(comparison.final, target, diagnosis.findings)
        if equation:
            out.append(f"    {equation}")
            notes += _sign_notes(comparison.final, target)
    out += ["", *_final_values(comparison.final), *notes]
    return out + non_physical(diagnosis)


def fitted_ranges(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """Per finding, the range of the states (or input) it was fitted over, in display units:
    outside it the finding is an extrapolation."""
    model = comparison.series.model
    units = dict(zip(model.state_names, model.state_units, strict=True)) | dict(
        zip(model.input_names, model.input_units, strict=True))
    rows = [f"- {k}. `{f.effect}` on `{f.target}`: " + ", ".join(
        f"{name} in {span(low, high, units.get(name, ''))}"
        for name, (low, high) in f.fitted_range.items())
        for k, f in enumerate(diagnosis.findings, 1) if f.fitted_range]
    if not rows:
        return []
    return ["Each finding holds over the range it was fitted on (the fitted model's free "
            "simulation of the records); outside it, it is an extrapolation:", "", *rows]


def non_physical(diagnosis: Diagnosis) -> list[str]:
    """The candidates refused because their sign makes the motion less stable than the
    linear model over the recorded range."""
    if not diagnosis.non_physical:
        return []
    return ["Refused as non-physical (the next admissible candidate was taken instead):", "",
            *(f"- round {t['round']}: `{t['candidate']}` (held-out improvement "
              f"{_percent(t['improvement'])}): {t['reason']}." for t in diagnosis.non_physical),
            ""]


def _sign_notes(final: Fit, target: str) -> list[str]:
    """A warning per negative damping or restoring coefficient of the final equation."""
    form = standard_form(final, target)
    words = {"B1": "linear damping", "B2": "quadratic damping", "B3": "cubic damping",
             "C1": "linear restoring"}
    out = [f"**Note:** {key} < 0 in the equation of `{target}`: negative {word}. Alone it "
           "would feed the motion; here it only reshapes the other terms over the amplitudes "
           "recorded, do not extrapolate it." for key, word in words.items()
           if form.get(key, 0.0) < 0]
    return [line for note in out for line in (note, "")]


def _equation(final: Fit, target: str, findings: Sequence[Finding]) -> str:
    """``target' = -B1 x - B2 x|x| - ...`` with the final fit's numbers (signs folded in)."""
    model = final.structure.series.model
    if target not in model.state_names:
        return ""
    form = standard_form(final, target)
    source = next((f.parameters["source"] for f in findings
                   if f.target == target and "source" in f.parameters), None)
    if source is None and "C1" in form:
        A = model.linearize()[0]
        i = model.state_names.index(target)
        sources = [q for q in np.flatnonzero(A[i]) if q != i]
        source = model.state_names[sources[-1]] if sources else "q"
    signed = [(-form[key], shape.format(x=target, q=source)) for key, shape in STANDARD_TERMS
              if form.get(key, 0.0) != 0.0]
    signed += [(value, key[2:]) for key, value in form.items() if key.startswith("G_")]
    if not signed:
        return ""
    terms = [f"{'-' if value < 0 else '+'} {abs(value):.4g} {shape}" for value, shape in signed]
    others = [t for t in final.structure.terms if t.target == target and t.effect not in
              ("linear_damping", "quadratic_damping", "nonlinear_damping", "coupling",
               "nonlinear_restoring")]
    joined = " ".join(terms)
    text = f"{target}' = " + (joined[2:] if joined.startswith("+") else "-" + joined[2:])
    return text + (" + (other terms)" if others else "")


def _final_values(final: Fit) -> list[str]:
    """The final fit's parameters and term coefficients (initial states left out)."""
    structure = final.structure
    count = len(structure.names) + len(structure.terms)
    labels = structure.labels()[:count]
    if not labels:
        return []
    rows = [f"| `{label}` | {num(float(final.theta[k]))} | {num(float(final.std[k]))} |"
            for k, label in enumerate(labels)]
    return ["| unknown of the final model | value | std |", "| --- | ---: | ---: |", *rows, ""]


def _held_out(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """Held-out free-simulation RMS per channel before and after, the validation sentence and
    the combined improvement."""
    fit_ = diagnosis.fit
    before = fit_.get("before", {}).get("rmse", {})
    after = fit_.get("after", {}).get("rmse", {})
    noise = fit_.get("noise_rmse", {})
    if not before:
        return []
    units = _units(diagnosis)
    rows = []
    for c, b in before.items():
        unit = units.get(c, "")
        shown = display_unit(unit)[1]
        a = after.get(c, b)
        rows.append(f"| {c} | {unit}" + (f" ({shown})" if shown != unit else "") + " | "
                    f"{with_degrees(noise[c], unit) if c in noise else '–'} | "
                    f"{with_degrees(b, unit)} | {with_degrees(a, unit)} | {change(b, a)} |")
    improvement = fit_.get("improvement")
    combined = ("the model with the findings **diverged** in the held-out free simulation"
                if improvement == "diverged" else
                f"{_percent(improvement)} of the held-out error in excess of the sensor noise "
                "removed")
    return ["## Held-out free simulation", "",
            f"Validation: {fit_.get('validation', '')}.", "",
            "| channel | unit | sensor noise (RMS) | RMS before | RMS after | change |",
            "| --- | --- | ---: | ---: | ---: | ---: |", *rows, "",
            f"Combined improvement: {combined}." if comparison.accepted else
            "No term was accepted: the calibrated nominal model is the final model.", ""]


def _alternatives(diagnosis: Diagnosis) -> list[str]:
    if not diagnosis.findings:
        return []
    out = ["## Alternatives", ""]
    if not diagnosis.alternatives:
        comparison = diagnosis.comparison
        tie = comparison.config.tie if comparison is not None else 0.1
        return out + [f"None: every accepted term beat the other candidates of its round by "
                      f"more than {tie:.0%} of the held-out error.", ""]
    out += ["Terms the held-out data cannot tell apart (within "
            f"{diagnosis.comparison.config.tie:.0%} of the held-out error); the chosen one "
            "is reported, the other would do as well:", ""]
    for alt in diagnosis.alternatives:
        out.append(f"- `{alt['chosen']}` (chosen) or `{alt['equally']}`: to separate them, "
                   f"{alt['separate_by']}.")
    return out + [""]


def _class_limit(diagnosis: Diagnosis) -> str:
    """The verdict's sentence when the correction makes a held-out amplitude class worse."""
    verdict_ = diagnosis.across_classes.get("verdict", "")
    return f" **But {verdict_}** (see *Across amplitude classes*)." if verdict_ else ""


def spread_lines(diagnosis: Diagnosis) -> list[str]:
    """Each coefficient's statistical std beside its spread between records (or pieces of
    one), the larger reported; the amplitude terms that swap with the record's span."""
    spread = diagnosis.fit.get("between_records")
    if not spread or len(spread["records"]) < 2:
        return []
    out = ["## Spread between records", "",
           f"Method: {spread['method']}. The uncertainty reported for each coefficient (in the "
           "findings and the verdict) is the larger of its statistical std (from the residuals, "
           "which assume the model is right) and this spread.", "",
           "| coefficient | value | statistical std | spread | per record: "
           + ", ".join(cell(r) for r in spread["records"]) + " |",
           "| --- | ---: | ---: | ---: | --- |"]
    for label, c in spread["coefficients"].items():
        wider = " **(reported)**" if c["spread"] > c["statistical_std"] else ""
        out.append(f"| `{label}` | {num(c['value'])} | {num(c['statistical_std'])} | "
                   f"{num(c['spread'])}{wider} | {', '.join(num(v) for v in c['per_record'])} |")
    out.append("")
    out += [f"- {swap['sentence'][0].upper()}{swap['sentence'][1:]}." for swap in spread["swaps"]]
    return out + ([""] if spread["swaps"] else [])


def across_classes_lines(diagnosis: Diagnosis) -> list[str]:
    """The leave-one-amplitude-class-out table and a sentence per class the correction
    makes worse."""
    across = diagnosis.across_classes
    if not across:
        return []
    channel = across["channel"]
    key = "rerun_rmse" if across.get("judged") == "re-run" else "rmse"  # what was judged
    unit = _units(diagnosis).get(channel, "")
    factor, shown = display_unit(unit)
    correction = ", ".join(f"`{f.effect}` on `{f.target}`" for f in diagnosis.findings) \
        or "the correction"
    out = ["## Across amplitude classes", "", f"Validation: {across['method']} (amplitudes "
           f"within {across['tolerance']:.0%} form a class). RMS error in `{channel}` ({shown}):",
           "", "| held-out class | records | fitted on | nominal-calibrated | corrected | cut |",
           "| --- | --- | --- | ---: | ---: | ---: |"]
    for row in across["classes"]:
        before = row["nominal"][key][channel] * factor
        after = row["corrected"][key][channel] * factor
        out.append(f"| {cell(row['class'])} | {cell(', '.join(row['records']))} | "
                   f"{cell(_listed(row['fitted_on']))} | {before:.3g} | {after:.3g} | "
                   f"{'diverged' if row['corrected']['diverged'] else format(row['cut'], '.0%')} |")
    out.append("")
    for row in across["classes"]:
        if row["worse"]:
            before = row["nominal"][key][channel] * factor
            after = row["corrected"][key][channel] * factor
            out.append(f"- Fitted on {_listed(row['fitted_on'])}, {correction} makes the "
                       f"{row['class']} test worse: {before:.3g} -> {after:.3g} {shown}.")
    tried = across.get("richer", {})
    out += [f"- {sentence[0].upper()}{sentence[1:]}." for sentence in tried.values()]
    if across["worse"]:
        untried = [m for m in across.get("richer_models", []) if m not in tried]
        out.append("- " + across["verdict"][0].upper() + across["verdict"][1:] + (
            f"; richer host models to try: {', '.join(untried)}." if untried else
            "." if tried else "; no richer host model is declared for this one."))
    return out + [""]


def _listed(names: Sequence[str]) -> str:
    """``a, b and c``."""
    return " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)


def _unexplained(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    out = ["## Unexplained", ""]
    factor = comparison.config.noise_factor
    if not diagnosis.unexplained:
        return out + [f"Nothing: the final model's held-out error is within {factor:g}× the "
                      "sensor noise.", ""]
    units = _units(diagnosis)
    rows = [f"| {c} | {with_degrees(v['rmse'], units.get(c, ''))} | "
            f"{_percent(v['share_of_signal'])} |" for c, v in diagnosis.unexplained.items()]
    out += [f"The final model's held-out free-simulation error stays above {factor:g}× "
            "the sensor noise: physics neither the model nor the catalogue holds (or a "
            "term whose coefficient changes between the fitted and held-out parts).", "",
            "| channel | RMS held-out error | share of the signal's RMS |",
            "| --- | ---: | ---: |", *rows, ""]
    if diagnosis.not_kept:
        out += ["The candidates of the last round, and why none was kept:", "",
                "| candidate | held-out improvement | why not kept |", "| --- | ---: | --- |",
                *(f"| `{t['candidate']}` | {_percent(t['improvement'])} | {t['reason']} |"
                  for t in diagnosis.not_kept), ""]
    return out


def how_to_read(comparison: Comparison) -> str:
    """The method in a paragraph, with this comparison's configuration."""
    config = comparison.config
    held = (f"the last {1 - config.fit_fraction:.0%} of the record, predicted by continuing the "
            f"simulation fitted on the first {config.fit_fraction:.0%} (for a decay: the small "
            "amplitudes the fit did not see)" if len(comparison.series.runs) == 1 else
            "each recording, predicted by the model fitted on the others (only its own initial "
            "state fitted to it)")
    return f"""\
**Free simulation.** The model starts where the record starts (its initial states fitted) and
is driven by the recorded inputs only, never corrected by the measurements: the whole time
history must come out of its equations. A model right only over a few seconds or at one
amplitude fails this test. The calibrated parameters, the terms' coefficients and the initial
states are fitted by least squares on the whole history (output error). A catalogue term is
added, everything refitted, and the term kept only when it removes at least
{config.min_gain:.0%} of the error in excess of the sensor noise on data no fit has seen:
{held}. Each finding's *improvement* is its share of that excess error; its *confidence* falls
with its coefficient's relative standard deviation and halves when a competitor explains the
data as well (see Alternatives).

**Standard form.** Each force equation with a finding is written per unit inertia as
`x' = -B1 x - B2 x|x| - B3 x^3 - C1 q - C3 q^3 + G_u u`, x the state of the equation (the
roll rate p for roll), q its restoring source (the roll angle phi) and u each input that moves
in the records: B1 linear, B2 quadratic and B3 cubic damping; C1 linear restoring (the natural
frequency squared) and C3 cubic restoring (C3 > 0 stiffening: the period shortens with
amplitude; C3 < 0 softening); G_u the input's gain (Nomoto's K/T, with B1 = 1/T). A negative B
lowers the damping at large amplitude; next to another damping form it usually trades off with
it over the amplitudes recorded.

**Figures.** In the time histories a right model's orange curve lies on the black record in
the shaded (held-out) part too; the errors should shrink to the dotted noise band. On the
extinction curves, linear damping gives a flat logarithmic decrement, quadratic damping one
rising linearly with amplitude, cubic one rising with its square; a constant period is linear
restoring. The corrected model should follow the measured points down to small amplitudes."""


def _percent(value: Any) -> str:
    return f"{value:.0%}" if isinstance(value, int | float) and not isinstance(value, bool) \
        else str(value)
