"""A record in a seaway, judged by the nominal filter's innovations (steps 2-5 of
:mod:`.api`).

1. Check the record (length, excitation) before any work.
2. Optionally calibrate named nominal parameters first (so only what the model's *structure*
   leaves out remains).
3. Smooth the record with the nominal model; locate the mismatch (channels, time windows,
   frequency band) in its multi-step prediction errors.
4. Search the catalogue (:mod:`.hypotheses`, :mod:`.selection`) and report each supported effect
   with its parameters, their standard deviations, a confidence and an explanation. When a
   finding acts on a state no channel measures, smooth again with the findings in the model and
   search again, until the findings repeat (the nominal smoothing attenuates that state).
5. Validate: the held-out prediction error before and after adding the findings; withdraw what
   the held-out part does not confirm.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal

from marine_envs.models import VehicleModel
from marine_envs.models.effects import Effect, EffectModel
from marine_envs.recording import Recording

from . import feedback
from .explain import explain, separating_test
from .output_error import Coordinates, parameter_bounds, term_label
from .residuals import (
    Residuals,
    equation_error,
    estimate,
    observable_states,
    white_noise_std,
)
from .result import Diagnosis, Finding
from .rollout import Rollouts
from .selection import (
    DiagnosisConfig,
    Evaluator,
    Fitted,
    Scored,
    Selection,
    fit_findings,
    gain_test,
    select,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: Below these a recording is too short to say anything.
MIN_SAMPLES, MIN_DURATION = 300, 60.0
#: The stages of a record in a seaway, as :func:`diagnose` reports them to ``stage``.
SEAWAY_STAGES = ("calibrating", "smoothing", "searching", "re-smoothing", "validating")
#: Called at the start of each stage: its name, its index from 0, and the number of stages.
Stage = Callable[[str, int, int], None]
#: The smallest effect the diagnosis is held to judge changes a channel's motion by this share
#: of its spread (RMS; issue 57's floor: no record refused whose effect changes the motion by
#: 15 % or more). The catalogue's typical effects (``synthetic.typical_effect`` at strength
#: 0.3) changed the environments' recorded motion by 20-178 %.
DETECTABLE_SHARE = 0.15
#: Such an effect is detectable when it stands this many standard errors above the sensor
#: noise accumulated over the record (:func:`excitation`): the search's level after its
#: Bonferroni correction (0.01 over about 100 families, z = 3.7), and the held-out
#: confirmation's (z = 2.3 on the last 30 % is 4.2 over the whole record), with a margin.
DETECTABLE_Z = 5.0
#: A record whose best channel is this many times short of :data:`DETECTABLE_Z` (it would
#: take this squared times the record) shows no motion beyond the noise: excite it instead.
HOPELESS = 5.0
#: The motion's variance must exceed the sensor noise's by this many sampling deviations of
#: their ratio, or the channel is taken as still.
STILL_DEVIATIONS = 3.0
#: The sampling deviation of that ratio for white noise, times sqrt(samples): its deviation is
#: estimated from fourth differences (:func:`.residuals.white_noise_std`); 2.7-2.8 over 200
#: draws each of 300, 1200, 3000 and 30000 samples.
NOISE_RATIO_SPREAD = 2.8
#: A model whose predictions are this many times (RMS) worse than holding the last sample does
#: not describe the recording, unless its findings bring them back within.
WORSE_THAN_HOLDING = 2.0
#: A finding judged on the held-out innovations (:func:`judged_on_innovations`) is still
#: withdrawn when its held-out predictions are worse by this many standard errors
#: (:meth:`Rollouts.improvement_z`): on effect-free USV records made by ``marine simulate``
#: (seeds 0-3, tuning), a sway coupling and a sway ``psi*phi`` term that predicted the
#: held-out innovations (p = 7e-4, 2e-3) made the predictions 3 % worse at 2.1 and 1.7 standard
#: errors; the right hovercraft sway restoring force without the sway speed, -3 % at 0.4.
WORSE_PREDICTIONS = 1.0
#: At most this many searches on states smoothed with the last one's findings
#: (:func:`_resmoothed`), each a smoothing and a search; a linear roll damping without the
#: roll rate came out at 50, 86 and 93 % of the truth on the first three.
RESMOOTHING_PASSES = 3


def diagnose_seaway(recordings: Sequence[Recording], vehicle: VehicleModel,
                    calibrate: Sequence[str], config: DiagnosisConfig,
                    log: Callable[[str], None] | None, stage: Stage | None = None) -> Diagnosis:
    """The diagnosis of one record in a seaway (the module doc's steps); ``log`` and
    ``stage`` as :func:`.api.diagnose` takes them."""
    def begin(name: str) -> None:
        if stage is not None:
            stage(name, SEAWAY_STAGES.index(name), len(SEAWAY_STAGES))

    if len(recordings) > 1:
        raise ValueError("a series of recordings is judged in free simulation only: "
                         "use method='free' (or 'auto')")
    recording = recordings[0]
    problem = check(recording, vehicle)
    if problem:
        return Diagnosis(vehicle.name, None, problem)
    if log is not None:
        log(f"smoothing {len(recording.time)} samples with the nominal model and searching the "
            "catalogue (a few seconds)...")
    calibration: dict[str, float] = {}
    quality: dict[str, Any] = {}
    if calibrate:
        begin("calibrating")
        vehicle, calibration, quality = _calibrate(recording, vehicle, calibrate)
    begin("smoothing")
    residuals = estimate(recording, vehicle)
    rollouts = Rollouts(residuals, config.fit_fraction, config.horizon, config.stride)
    # a missing actuator effect can make the nominal predict worse than holding (a flap's
    # delay or dead zone), so a model is called wrong only if its findings cannot mend it
    nominal = _worse_than_holding(rollouts, rollouts.errors([]), rollouts.fit)
    begin("searching")
    first = select(residuals, config)
    begin("re-smoothing")
    selection = _resmoothed(recording, residuals, first, config)
    begin("validating")
    diagnosis = _judged(vehicle, residuals, rollouts, selection, config)
    if selection is not first and diagnosis.unconfirmed:
        # the innovations' response to a term is linearised about the nominal states, so a
        # term searched on states smoothed with the findings can fail its confirmation where
        # the nominal search's own term passes (a hydrofoil cross term without the rates)
        fallback = _judged(vehicle, residuals, rollouts, first, config)
        if len(fallback.findings) > len(diagnosis.findings):
            diagnosis = fallback
            diagnosis.fit["search"] = ("the nominal smoothing's: the findings searched on "
                                       "states smoothed with them were not confirmed")
    diagnosis.calibration, diagnosis.calibration_quality = calibration, quality
    diagnosis.fit["excitation"] = excitation(recording).to_dict()
    selection = diagnosis.selection
    if nominal > WORSE_THAN_HOLDING:
        assert selection.validated_errors is not None
        mended = _worse_than_holding(rollouts, selection.validated_errors, rollouts.held)
        if not diagnosis.findings or mended > WORSE_THAN_HOLDING:
            return Diagnosis(vehicle.name, None, _wrong_model(rollouts, nominal, diagnosis),
                             calibration=calibration, residuals=residuals, rollouts=rollouts,
                             unconfirmed=diagnosis.findings + diagnosis.unconfirmed)
        diagnosis.model_check = {"worse_than_holding": {"nominal": round(nominal, 2),
                                                        "with_findings": round(mended, 2)}}
    return diagnosis


def _judged(vehicle: VehicleModel, residuals: Residuals, rollouts: Rollouts,
            selection: Selection, config: DiagnosisConfig) -> Diagnosis:
    """The diagnosis of a search's ``selection``: its findings located, validated on the
    held-out part and confirmed there."""
    findings = [_finding(s, residuals) for s in selection.findings]
    diagnosis = Diagnosis(vehicle.name, bool(findings), "", residuals=residuals,
                          rollouts=rollouts, selection=selection, findings=findings)
    _locate(diagnosis)
    _validate(diagnosis, config)
    _confirm(diagnosis, config)
    diagnosis.alternatives = _alternatives(selection)
    return diagnosis


def other_model(recording: Recording, vehicle: VehicleModel) -> str:
    """The reason given for a recording of another model."""
    return (f"the recording is of model {recording.model!r}, not {vehicle.name!r}: "
            f"diagnose it with --model {recording.model}")


# -- checks ---------------------------------------------------------------------------------------
def check(recording: Recording, vehicle: VehicleModel) -> str:
    """Why the recording cannot be diagnosed against ``vehicle``, or ``""``."""
    if recording.model != vehicle.name:
        return other_model(recording, vehicle)
    n, duration = len(recording.time), float(recording.time[-1] - recording.time[0])
    if n < MIN_SAMPLES or duration < MIN_DURATION:
        return (f"too short to say anything: {n} samples over {duration:.1f} s; need at least "
                f"{MIN_SAMPLES} samples and {MIN_DURATION:.0f} s (30 % of it is held out) to "
                "judge a record in a seaway; a model test (decay, zigzag, lab run) is judged "
                "in free simulation: --method free, or several recordings as one series")
    if not observable_states(vehicle, recording.measured_names).any():
        return "the measured channels observe no state"
    seen = excitation(recording)
    if seen.z < DETECTABLE_Z:
        return seen.refusal(recording)
    return ""


@dataclass(frozen=True)
class Excitation:
    """How well a record shows an effect of :data:`DETECTABLE_SHARE` of its motion.

    :param channel: the channel that shows it best.  :param z: its standard errors there.
    :param smallest: the smallest share of that channel's motion an effect must change to
        stand :data:`DETECTABLE_Z` standard errors out of the noise.
    :param duration: the record's length, s.
    """

    channel: str
    z: float
    smallest: float
    duration: float

    def to_dict(self) -> dict[str, Any]:
        return {"channel": self.channel, "z": round(self.z, 1),
                "smallest_detectable_share": round(self.smallest, 3)}

    def refusal(self, recording: Recording) -> str:
        """Why the record cannot be judged, and what would make it judgeable."""
        shortfall = DETECTABLE_Z / max(self.z, 1e-3)
        still = [name for name, u in zip(recording.input_names, recording.inputs.T,
                                         strict=True) if not _moves(u[np.isfinite(u)])]
        if shortfall > HOPELESS:
            motion = ("no measured channel moves beyond its sensor noise "
                      f"({', '.join(recording.measured_names)})")
            advice = "excite the vehicle (inputs, a release from an offset) and record again"
        else:
            motion = (f"an effect changing the motion by {DETECTABLE_SHARE:.0%} would stand "
                      f"{self.z:.1f} standard errors out of the sensor noise at best "
                      f"({self.channel}), {DETECTABLE_Z:g} are needed")
            advice = (f"record {shortfall**2:.1f}x as long (at least "
                      f"{self.duration * shortfall**2:.0f} s), or excite the vehicle so that "
                      f"{self.channel} moves {shortfall:.1f}x as much")
        if still:
            advice += f"; the input(s) {', '.join(still)} do not move: a dither or steps on them"
        return f"no excitation: {motion}; {advice}"


def excitation(recording: Recording) -> Excitation:
    """How many standard errors an effect changing a channel's motion by
    :data:`DETECTABLE_SHARE` of its spread stands out of the sensor noise over the record,
    in the channel that shows it best: the effect's signature fitted against white sensor
    noise, accumulated over the channel's samples, ``z = share * A / sigma * sqrt(N)``, with
    ``A`` the spread of the motion beyond the noise (:data:`STILL_DEVIATIONS`)."""
    best = Excitation("", 0.0, math.inf, float(recording.time[-1] - recording.time[0]))
    for name, y in zip(recording.measured_names, recording.measurements.T, strict=True):
        y = y[np.isfinite(y)]
        if len(y) < 5:
            continue
        sigma = float(white_noise_std(y[:, None])[0])
        ratio = float(np.var(y)) / sigma**2 - 1 \
            - STILL_DEVIATIONS * NOISE_RATIO_SPREAD / math.sqrt(len(y))
        accumulated = math.sqrt(max(ratio, 0.0) * len(y))  # A / sigma * sqrt(N)
        if DETECTABLE_SHARE * accumulated > best.z:
            best = replace(best, channel=name, z=DETECTABLE_SHARE * accumulated,
                           smallest=DETECTABLE_Z / accumulated)
    return best


def _moves(u: FloatArray) -> bool:
    return bool(u.size) and float(np.ptp(u)) > 0


def _worse_than_holding(rollouts: Rollouts, errors: FloatArray, rows: BoolArray) -> float:
    """How many times (RMS, over the starts ``rows``) predictions with the per-start weighted
    ``errors`` of :meth:`Rollouts.errors` are worse than holding the last sample."""
    held = rollouts.target - rollouts.res.y[rollouts.starts][:, None, :]
    hold = float(np.sum(held[rows] ** 2 * rollouts.weights))
    return math.sqrt(float(errors[rows].sum()) / max(hold, 1e-300))


def _wrong_model(rollouts: Rollouts, nominal: float, diagnosis: Diagnosis) -> str:
    """Why the model does not describe the recording: its predictions are worse than holding
    the last sample, and still with its findings (wrong model or wrong parameters)."""
    tried = ", ".join(f"{f.effect} on {f.target}" for f in diagnosis.findings)
    return (f"the model does not describe this recording: its {rollouts.steps}-step "
            f"predictions are {nominal:.1f}x worse than assuming nothing moves"
            + (f", and still more than {WORSE_THAN_HOLDING:g}x with the catalogue's findings "
               f"({tried})" if tried else "")
            + ". Check the model name, the units and the parameters (--params, --calibrate)")


def _calibrate(recording: Recording, vehicle: VehicleModel, names: Sequence[str]
               ) -> tuple[VehicleModel, dict[str, float], dict[str, Any]]:
    """Fit the named parameters by equation-error least squares on the smoothed states (two
    passes: the smoother is rerun with the calibrated model). A parameter the measured states'
    equations do not contain is left as it was and reported so, never passed off as
    calibrated."""
    values = {n: float(getattr(vehicle.params, n)) for n in names}
    quality: dict[str, Any] = {"parameters": {}}
    for _ in range(2):
        values, free, converged = _equation_fit(estimate(recording, vehicle), values)
        quality["converged"] = converged
        vehicle = vehicle.with_params(**values)
    for n in names:
        quality["parameters"][n] = {
            "value": values[n],
            "status": "identified" if n in free else
            "not identifiable: the equations of the measured channels do not contain it"}
    return vehicle, {n: values[n] for n in free}, quality


def _equation_fit(residuals: Residuals, values: dict[str, float]
                  ) -> tuple[dict[str, float], list[str], bool]:
    """One pass of :func:`_calibrate`: scipy's bounded trust region on the measured states'
    equation errors; the values, the names the equations contain, and convergence."""
    vehicle = residuals.model
    x, u = residuals.midpoint, residuals.u[:-1]
    measured = [i for i, s in enumerate(vehicle.state_names) if s in residuals.channels]
    scale = 1 / np.sqrt(np.maximum(np.var(residuals.error[:, measured], axis=0), 1e-300)
                        * len(x))
    target = (residuals.error + vehicle.rhs(x, u))[:, measured]

    def errors(z: FloatArray, free: Sequence[str]) -> FloatArray:
        trial = {**values, **dict(zip(free, z.tolist(), strict=True))}
        with np.errstate(all="ignore"):
            e = (vehicle.rhs_with(x, u, None, trial)[:, measured] - target) * scale
        return np.clip(np.nan_to_num(e, nan=1e6), -1e6, 1e6).ravel()

    base = errors(np.array([]), ())
    free = [n for n in values
            if np.any(errors(np.array([values[n] * 1.01 + 1e-6]), [n]) != base)]
    if not free:
        return values, free, True
    low, high = parameter_bounds(vehicle, free)
    coordinates = Coordinates(vehicle, free, range(len(free)))  # a lag may turn unstable
    start = coordinates.solver(np.clip([values[n] for n in free], low, high))
    fit = optimize.least_squares(lambda z: errors(coordinates.unknowns(z), free), start,
                                 bounds=coordinates.bounds(low, high), x_scale="jac")
    fitted = coordinates.unknowns(fit.x)
    return {**values, **dict(zip(free, fitted.tolist(), strict=True))}, free, bool(fit.success)


# -- locate ---------------------------------------------------------------------------------------
def _locate(diagnosis: Diagnosis) -> None:
    """Channels ranked by their share of the excess prediction error, windows where it
    concentrates, and the frequency band that holds most of it."""
    ro, res = diagnosis.rollouts, diagnosis.residuals
    assert ro is not None and res is not None
    error = ro.nominal_error  # (S, H, m)
    excess = np.maximum(np.mean(error**2, axis=(0, 1)) - res.noise**2, 0.0)
    share = excess * ro.weights
    total = share.sum()
    ranked = sorted(zip(res.channels, share / total if total > 0 else share, strict=True),
                    key=lambda item: -item[1])
    diagnosis.channels = [{"name": c, "score": round(float(s), 4)} for c, s in ranked]
    diagnosis.windows = _windows(ro, res, ranked[0][0] if total > 0 else None)
    diagnosis.band = _band(res, ranked[0][0] if total > 0 else None)


def _windows(ro: Rollouts, res: Residuals, channel: str | None,
             length: float = 30.0) -> list[dict[str, Any]]:
    """Time windows whose prediction error in ``channel`` is well above its median."""
    if channel is None:
        return []
    j = res.channels.index(channel)
    per_start = np.mean(ro.nominal_error[..., j] ** 2, axis=1)
    times = res.time[ro.starts]
    edges = np.arange(times[0], times[-1] + length, length)
    level = np.array([per_start[(times >= a) & (times < a + length)].mean()
                      if np.any((times >= a) & (times < a + length)) else 0.0 for a in edges])
    if not np.any(level > 0):
        return []
    hot = level > 2 * np.median(level[level > 0])
    return [{"start": float(a), "end": float(a + length), "channel": channel}
            for a, h in zip(edges, hot, strict=True) if h]


def _band(res: Residuals, channel: str | None) -> dict[str, float] | None:
    """The frequency band (rad/s) holding the middle 80 % of the equation-error power of the
    state behind ``channel``."""
    if channel is None or channel not in res.model.state_names:
        return None
    e = res.error[:, res.model.state_names.index(channel)]
    f, psd = signal.welch(e, fs=1 / res.dt, nperseg=min(len(e), max(8, int(60 / res.dt))))
    cumulative = np.cumsum(psd) / max(psd.sum(), 1e-300)
    omega = 2 * np.pi * f
    low = omega[np.searchsorted(cumulative, 0.1)]
    high = omega[min(np.searchsorted(cumulative, 0.9), len(omega) - 1)]
    return {"low": round(float(low), 3), "high": round(float(high), 3)}


# -- unmeasured states smoothed with the findings ---------------------------------------------
def _state_terms(selection: Selection) -> list[Effect]:
    """The findings a smoother can carry: time-invariant state terms."""
    return [s.fitted.effect for s in selection.findings if s.fitted.effect.kind == "state"
            and s.fitted.effect.effect not in ("wave_frequency", "parameter_change")]


def _unmeasured(effects: Sequence[Effect], residuals: Residuals) -> set[str]:
    """The unmeasured states the state terms among ``effects`` act on."""
    return {e.target for e in effects if e.kind == "state" and e.target not in residuals.channels}


def _resmoothed(recording: Recording, residuals: Residuals, selection: Selection,
                config: DiagnosisConfig) -> Selection:
    """Smooth again with the findings in the model and search again, until the findings repeat
    (an expectation-maximisation iteration). A state no channel measures follows the nominal
    model in the smoother, which lacks the very term that acts on it; the terms fitted to that
    state are attenuated (errors in the variables: a roll damping fitted to a nominally
    smoothed roll rate came out a third of the truth and looked quadratic). The innovations
    stay the nominal filter's: only the states the terms are functions of change. Validation
    stays on the nominal smoothing (:func:`_validate` refits the chosen terms there), so the
    nominal model is not judged from states that already know the findings.

    Only for models whose sensors read states: the DP vessel's position reference reads the
    sum of its low- and wave-frequency motion, and its velocities come out of the model's own
    sea model; searched again, 2 of its first 13 tuned cases moved to a wrong term."""
    model = residuals.model
    if model.output_names != model.state_names:
        return selection
    for _ in range(RESMOOTHING_PASSES):
        carried = _state_terms(selection)
        if not _unmeasured(carried, residuals):  # the nominal smoothing follows the data there
            break
        try:
            states = estimate(recording, EffectModel(model, carried))
        except ValueError:  # SmootherDiverged, or a noise model it left non-finite: a
            break           # fitted term that destabilises the model; keep the last search
        candidate = replace(residuals, x=states.x, x_std=states.x_std, error=equation_error(
            model, states.x, residuals.u, residuals.dt, residuals.substeps))
        again = select(candidate, config)
        if not _unmeasured(carried, residuals) <= _unmeasured(_state_terms(again), residuals):
            break  # not a fixed point: the terms smoothed with are not found again
        repeated, selection = _repeats(selection, again), again
        if repeated:
            break
    return selection


def _repeats(before: Selection, after: Selection, tolerance: float = 0.05) -> bool:
    """Whether two searches found the same terms with parameters within ``tolerance``."""
    if [s.family.key for s in before.findings] != [s.family.key for s in after.findings]:
        return False
    for a, b in zip(before.findings, after.findings, strict=True):
        for name, value in a.fitted.effect.parameters.items():
            other = b.fitted.effect.parameters.get(name)
            if isinstance(value, int | float) and isinstance(other, int | float) and \
                    abs(other - value) > tolerance * max(abs(value), 1e-12):
                return False
    return True


# -- findings and validation ----------------------------------------------------------------------
def _finding(scored: Scored, residuals: Residuals) -> Finding:
    effect = scored.fitted.effect
    return Finding(effect.effect, effect.target, dict(effect.parameters),
                   {k: float(v) for k, v in scored.fitted.std.items()},
                   round(float(scored.confidence), 4), round(float(scored.alone), 4),
                   explain(effect, scored, residuals))


def _validate(diagnosis: Diagnosis, config: DiagnosisConfig) -> None:
    """Held-out multi-step prediction errors per channel before and after the findings, the
    findings refitted on the first part of the record only; each term alone and all together;
    and whether each term predicts the held-out part's innovations (:func:`_held_out_test`)."""
    ro, selection, res = diagnosis.rollouts, diagnosis.selection, diagnosis.residuals
    assert ro is not None and selection is not None and res is not None
    rows = np.arange(len(res.time)) < int(ro.fit_fraction * len(res.time))
    fitted = fit_findings(res, Evaluator(res.innovations.nu, 1), selection.findings, rows) \
        if selection.findings else []
    effects, forcing, shift = findings_model(res, fitted)
    before = ro.errors([])
    for k, (scored, term) in enumerate(zip(selection.findings, fitted, strict=True)):
        alone = ro.errors(*findings_model(res, [term]))
        scored.alone = round(float(ro.improvement(before, alone)), 4)
        scored.alone_z = ro.improvement_z(before, alone, config.confirm_block)
        scored.on_innovations = judged_on_innovations(scored.effect, res)
        scored.held_out_p, scored.innovation_gain = _held_out_test(res, fitted, k, ~rows,
                                                                   config.confirm_block)
    selection.validated_errors = ro.errors(effects, forcing, shift)
    selection.combined_improvement = float(ro.improvement(before, selection.validated_errors))
    for finding, scored in zip(diagnosis.findings, selection.findings, strict=True):
        finding.improvement = _improvement(scored)
        finding.explanation = explain(scored.fitted.effect, scored, res)  # quotes it
    diagnosis.fit = {
        "before": {"rmse": ro.rmse([])},
        "after": {"rmse": ro.rmse(effects, forcing, shift)},
        "improvement": round(selection.combined_improvement, 4),
        "validation": (f"held-out last {1 - ro.fit_fraction:.0%}, findings refitted on the "
                       f"rest: {ro.steps}-step ({ro.steps * ro.res.dt:.1f} s) predictions from "
                       "the smoothed state, error in excess of the sensor noise" + "".join(
                           f"; {e.effect}:{e.target} evaluated on the smoothed states (in "
                           "the loop it predicted the first part worse)"
                           for e in effects if not ro.carries(e))),
        "expected_from_sea": round(ro.sea_share(before), 4),
        "terms": [{"effect": s.fitted.effect.effect, "target": s.fitted.effect.target,
                   "improvement": _improvement(s)} for s in selection.findings],
    }


def _improvement(scored: Scored) -> float:
    """A term's held-out improvement on the horizon that fits it (:func:`judged_on_innovations`):
    the share of the held-out innovations it removes, or of the prediction error."""
    return round(scored.innovation_gain, 4) if scored.on_innovations else scored.alone


def _held_out_test(res: Residuals, fitted: Sequence[Fitted], k: int, held_out: BoolArray,
                   block: float) -> tuple[float, float]:
    """Whether term ``k``, fitted on the first part with the others, predicts the held-out
    part's whitened innovations (those left by the others): the one-sided p-value of the
    search's test (:func:`.diagnosis.gain_test`) on data no fit has seen, over ``block``-s
    blocks, and the share of their sum of squares the term removes."""
    nu = res.innovations.nu - sum((f.response for j, f in enumerate(fitted) if j != k),
                                  np.zeros_like(res.innovations.nu))
    nu = nu[held_out]
    after = nu - fitted[k].response[held_out]
    gain = 1.0 - float(np.sum(after**2)) / max(float(np.sum(nu**2)), 1e-300)
    return gain_test(nu, after, int(round(block / res.dt)))[1], gain


def _confirm(diagnosis: Diagnosis, config: DiagnosisConfig) -> None:
    """Withdraw the findings whose own term, refitted on the first part, does not improve the
    held-out predictions or does not predict the held-out innovations at level ``alpha``: the
    search's evidence was the sea's colour or the noise, not a term the data repeat; and the
    input effects that do not hold on the part of the input the controller did not choose
    (:mod:`.feedback`). They are kept under ``unconfirmed``, with the reason; the rest are
    validated again.

    An actuator effect or a term on a state no channel measures improves the held-out data
    when it reduces the held-out innovations (:func:`judged_on_innovations`); the term on an
    unmeasured state, unless it makes the held-out predictions significantly worse
    (:data:`WORSE_PREDICTIONS`)."""
    selection, res = diagnosis.selection, diagnosis.residuals
    assert selection is not None and res is not None
    reasons = {k: _unconfirmed_because(s, res, config) for k, s in enumerate(selection.findings)}
    withdrawn = [k for k, why in reasons.items() if why]
    if not withdrawn:
        return
    diagnosis.unconfirmed += [replace(diagnosis.findings[k], withdrawn=reasons[k])
                              for k in withdrawn]
    selection.findings = [s for k, s in enumerate(selection.findings) if k not in withdrawn]
    diagnosis.findings = [f for k, f in enumerate(diagnosis.findings) if k not in withdrawn]
    diagnosis.mismatch = bool(diagnosis.findings)
    _validate(diagnosis, config)


def _unconfirmed_because(scored: Scored, res: Residuals, config: DiagnosisConfig) -> str:
    """Why a finding is withdrawn (:func:`_confirm`), or ``""``. Every finding must predict
    the held-out innovations and improve the held-out data on the horizon that fits it
    (:func:`judged_on_innovations`)."""
    if scored.held_out_p > config.alpha:
        return (f"refitted on the first part, it does not predict the held-out innovations "
                f"(p = {scored.held_out_p:.2g})")
    if judged_on_innovations(scored.effect, res):
        if scored.innovation_gain <= 0:
            return "refitted on the first part, it does not reduce the held-out innovations"
        if scored.alone_z < -WORSE_PREDICTIONS and not feedback.is_input_effect(scored.effect):
            return (f"refitted on the first part, it makes the held-out "
                    f"{config.horizon:g}-s predictions worse ({scored.alone:+.0%}, "
                    f"{-scored.alone_z:.1f} standard errors)")
    elif scored.alone <= 0:
        return "refitted on the first part, it does not improve the held-out predictions"
    if feedback.is_input_effect(scored.effect):
        check = feedback.check(res, scored.effect)
        if check is not None and not check.holds(config.alpha):
            return (f"the input follows the controller: on the part of it the controller did "
                    f"not choose, the term's coefficient is {check.instrumental:+.2f} +- "
                    f"{check.std:.2f} (p = {check.p_value:.2g}) against "
                    f"{check.least_squares:+.2f} on the whole input")
    return ""


def judged_on_innovations(effect: Effect, res: Residuals) -> bool:
    """Whether ``effect``'s held-out improvement is the share of the held-out innovations it
    removes (one step ahead, over the whole held-out part) rather than of the
    :class:`Rollouts`' few-second prediction error: an actuator effect (its applied input
    differs from the command along the whole record; a right rudder rate limit, active on 80 %
    of the samples, did not improve the 3-s predictions) and a term on a state no channel
    measures (the predictions start from the nominal smoother's estimate of that state, which
    lacks the term: a hovercraft sway restoring force right within 2 % removed -3 % of their
    error and predicted the held-out innovations at p = 2e-4)."""
    return feedback.is_input_effect(effect) or bool(_unmeasured([effect], res))


def _alternatives(selection: Selection) -> list[dict[str, Any]]:
    """Per finding, the other terms the record supports as well (its search round's rivals,
    :func:`.selection.rivals`), with their fitted parameters and a test that would separate
    them."""
    found = {s.family.key for s in selection.findings}
    return [{"chosen": term_label(s.effect), "equally": term_label(r.effect),
             "effect": r.effect.effect, "target": r.effect.target,
             "parameters": dict(r.effect.parameters),
             "separate_by": separating_test(s.effect, r.effect)}
            for s in selection.findings for r in s.rivals if r.family.key not in found]


def findings_model(res: Residuals, fitted: Sequence[Fitted]
           ) -> tuple[list[Effect], dict[int, FloatArray], FloatArray]:
    """Effects, wave forcings and smoothed-state shift of fitted findings, as
    :meth:`Rollouts.predict` takes them."""
    forcing = {k: f.details["forcing"] for k, f in enumerate(fitted) if "forcing" in f.details}
    shift = sum((res.innovations.smoothed_shift(f.w, f.v) for f in fitted),  # type: ignore
                np.zeros_like(res.x))
    return [f.effect for f in fitted], forcing, shift
