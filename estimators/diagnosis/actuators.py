"""The map from command to actuator position, judged directly where a record holds both.

A trial log holds the command (a recording's input columns); some vessels also log what the
actuator delivered, read by a position sensor on it (the columns ``<input>_applied``,
:data:`marine_envs.recording.APPLIED`). Where a record holds both, an input effect of the
catalogue (a gain, delay, saturation, dead zone or rate limit) is visible in the map from one to
the other without the hull's dynamics, its sea or its controller: the position is a known
function of the command plus the sensor's white noise, whatever made the command, so a least
-squares fit is consistent even in closed loop (unlike an input effect seen through the hull,
:mod:`.feedback`). The hull is then judged on the position (:func:`.residuals.model_inputs`).

Per actuator, effects are chosen greedily: each round fits every catalogue input effect not yet
chosen, before or after those that are, by its one parameter (a grid, then a bounded search)
on the first part of the record, and keeps the best if the error exceeds the sensor's noise
(:data:`MIN_EXCESS`), and the effect is significant (the fall in the squared error over the
noise's variance, a chi-squared test) and removes at least :data:`MIN_IMPROVEMENT` of the
held-out error in excess of that noise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, stats

from marine_envs.models import VehicleModel
from marine_envs.models.effects import INPUT_EFFECTS, KEY_PARAMETER, Effect, applied_inputs
from marine_envs.recording import APPLIED, Recording

from .residuals import white_noise_std
from .result import Diagnosis, Finding
from .selection import DiagnosisConfig

FloatArray = NDArray[np.float64]
#: A finding removes at least this share of the held-out error in excess of the sensor noise
#: (on tuning seeds 0 and 1 of benchmarks/env_recordings.py, each true effect removed 1.00;
#: every spurious candidate, on effect-free positions or beside a true effect, at most 0.12).
MIN_IMPROVEMENT = 0.5
#: Nothing is left to explain once the error is within this share of the sensor noise's
#: variance: the noise is estimated from the residual's fourth differences, within +-7 % (its
#: variance's sampling spread on 2100 samples); a 0.3-mrad dead zone beside an exactly fitted
#: rate limit removed "66 %" of an excess that was that scatter.
MIN_EXCESS = 0.25
#: At most this many effects per actuator (a rate limit and a saturation of one rudder).
MAX_EFFECTS = 3
#: Points of each parameter's grid before the bounded search.
GRID = 40
#: Blocks of the jackknife giving each parameter's standard deviation.
BLOCKS = 10
#: The longest delay tried, s.
MAX_DELAY = 3.0


@dataclass
class Segment:
    """One record's command and measured position of an actuator (full input rows, the
    actuator's column ``j``), and which samples the fit may use."""

    commanded: FloatArray
    position: FloatArray
    fit: NDArray[np.bool_]


@dataclass
class Chosen:
    """An actuator's effects (in the order they act) and what each one did."""

    effects: list[Effect]
    p_values: list[float]
    improvements: list[float]


def judge(recordings: Sequence[Recording], model: VehicleModel, config: DiagnosisConfig
          ) -> tuple[list[Finding], list[Recording]]:
    """The input effects the actuator position sensors of ``recordings`` show, as findings
    (none when the records hold no such sensor, or the positions follow the commands), and
    the recordings with each sensor's column replaced by the position those effects give the
    command (the command itself where there are none): the hull's input, without the
    sensor's noise. A Wiener filter cannot clear that noise from an autopilot's broadband
    command without cutting some of the command too; on the held-out effect-free USV records
    of benchmarks/env_recordings.py the hull then took the difference for roll damping and
    couplings, which it did not on the command."""
    names = [n for n in model.input_names if all(n in r.actuator_names for r in recordings)]
    findings: list[Finding] = []
    positions = [r.data.copy() for r in recordings]
    for name in names:
        j = list(model.input_names).index(name)
        segments = [_segment(r, model, j, config.fit_fraction) for r in recordings]
        chosen = choose(segments, model, j, recordings[0].dt, config.alpha)
        effects, found = _findings(chosen, segments, model, j, recordings[0].dt)
        findings += found
        for data, segment in zip(positions, segments, strict=True):
            data[name + APPLIED] = through(effects, segment, model, j, recordings[0].dt)
    return findings, [_like(r, data) for r, data in zip(recordings, positions, strict=True)]


def _like(recording: Recording, data: Any) -> Recording:
    """``recording`` with the table ``data`` (its missing samples and warnings kept)."""
    if not recording.actuator_names:
        return recording
    out = Recording(data, recording.model, recording.params, recording.meta,
                    require_uniform=False)
    out.gaps, out.warnings = recording.gaps, list(recording.warnings)
    return out


def _segment(recording: Recording, model: VehicleModel, j: int, fit_fraction: float) -> Segment:
    commanded = np.tile(model.u0, (len(recording.time), 1))
    commanded[:, j] = recording.inputs[:, j]
    fit = np.arange(len(recording.time)) < int(fit_fraction * len(recording.time))
    return Segment(commanded, recording.applied(model.input_names[j]), fit)


def through(effects: Sequence[Effect], segment: Segment, model: VehicleModel, j: int,
            dt: float) -> FloatArray:
    """The position the actuator takes under ``effects`` for the segment's command, starting
    where its sensor first read it (a rate-limited actuator moves on from there)."""
    u = np.vstack([segment.commanded[:1], segment.commanded])
    u[0, j] = segment.position[0]
    for effect in effects:
        u = applied_inputs(effect, model, u, dt)
    return u[1:, j]


def _errors(effects: Sequence[Effect], segments: Sequence[Segment], model: VehicleModel, j: int,
            dt: float) -> tuple[FloatArray, FloatArray]:
    """Position less its prediction under ``effects``: the fit samples', the held-out ones'."""
    residual = [s.position - through(effects, s, model, j, dt) for s in segments]
    return (np.concatenate([r[s.fit] for r, s in zip(residual, segments, strict=True)]),
            np.concatenate([r[~s.fit] for r, s in zip(residual, segments, strict=True)]))


def _grid(effect: str, segments: Sequence[Segment], model: VehicleModel, j: int,
          dt: float) -> FloatArray:
    """Values of ``effect``'s parameter to try, from the commands: each family's grid reaches
    its identity (a gain of 1, no delay, a limit beyond every command, ...)."""
    deviation = np.concatenate([np.abs(s.commanded[:, j] - model.u0[j]) for s in segments])
    slew = np.concatenate([np.abs(np.diff(s.commanded[:, j])) / dt for s in segments])
    levels = np.linspace(0.0, 1.0, GRID)
    if effect == "input_gain":
        return np.linspace(0.0, 2.0, GRID + 1)
    if effect == "input_delay":
        return dt * np.arange(0, int(round(MAX_DELAY / dt)) + 1)
    if effect == "input_saturation":
        return np.unique(np.quantile(deviation, 0.05 + 0.95 * levels)) * 1.0001
    if effect == "input_deadzone":
        return np.unique(np.quantile(deviation, 0.9 * levels))
    fastest = max(float(slew.max()), 1e-12)
    return np.geomspace(fastest * 1e-3, fastest * 1.0001, GRID)


def _fit(name: str, chain: list[Effect], at: int, segments: Sequence[Segment],
         model: VehicleModel, j: int, dt: float) -> tuple[Effect, float]:
    """Effect ``name``'s parameter fitted with it at position ``at`` of ``chain``: the effect
    and the fit samples' sum of squared errors."""
    key, target = KEY_PARAMETER[name], model.input_names[j]

    def sse(value: float) -> float:
        effects = [*chain[:at], Effect(name, target, {key: value}), *chain[at:]]
        return float(np.sum(_errors(effects, segments, model, j, dt)[0] ** 2))

    grid = _grid(name, segments, model, j, dt)
    values = np.array([sse(v) for v in grid])
    k = int(np.argmin(values))
    low, high = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    best, value = float(grid[k]), float(values[k])
    if high > low:
        found = optimize.minimize_scalar(sse, bounds=(low, high), method="bounded",
                                         options={"xatol": 1e-4 * max(abs(best), 1e-9)})
        if found.fun < value:
            best, value = float(found.x), float(found.fun)
    return Effect(name, target, {key: best}), value


def choose(segments: Sequence[Segment], model: VehicleModel, j: int, dt: float,
           alpha: float) -> Chosen:
    """The actuator's effects, greedily (module doc)."""
    chosen = Chosen([], [], [])
    for _ in range(MAX_EFFECTS):
        before_fit, before_held = _errors(chosen.effects, segments, model, j, dt)
        trials = [(_fit(name, chosen.effects, at, segments, model, j, dt), at)
                  for name in INPUT_EFFECTS if name not in {e.effect for e in chosen.effects}
                  for at in range(len(chosen.effects) + 1)]
        (effect, sse), at = min(trials, key=lambda trial: trial[0][1])
        effects = [*chosen.effects[:at], effect, *chosen.effects[at:]]
        after_fit, after_held = _errors(effects, segments, model, j, dt)
        noise = float(white_noise_std(after_fit[:, None])[0]) ** 2
        p_value = float(stats.chi2.sf((np.sum(before_fit**2) - sse) / max(noise, 1e-300), 1))
        improvement = _improvement(before_held, after_held, noise)
        explained = float(np.mean(before_fit**2)) <= (1 + MIN_EXCESS) * noise
        if explained or p_value > alpha or improvement < MIN_IMPROVEMENT:
            break
        chosen.effects.insert(at, effect)
        chosen.p_values.insert(at, p_value)
        chosen.improvements.insert(at, improvement)
    return chosen


def _improvement(before: FloatArray, after: FloatArray, noise: float) -> float:
    """The share of the error in excess of the sensor noise (variance ``noise``) removed."""
    excess = float(np.mean(before**2)) - noise
    if excess <= 0:
        return 0.0
    return 1.0 - max(float(np.mean(after**2)) - noise, 0.0) / excess


def _findings(chosen: Chosen, segments: Sequence[Segment], model: VehicleModel, j: int,
              dt: float) -> tuple[list[Effect], list[Finding]]:
    """The chosen effects refitted on the whole record (each with the others held), and
    as findings, with a block jackknife's standard deviation."""
    whole = [Segment(s.commanded, s.position, np.ones(len(s.position), bool)) for s in segments]
    effects = list(chosen.effects)
    for k, effect in enumerate(effects):
        effects[k] = _fit(effect.effect, effects[:k] + effects[k + 1:], k, whole, model, j,
                          dt)[0]
    out = []
    sensor = model.input_names[j] + APPLIED
    for k, effect in enumerate(effects):
        key = KEY_PARAMETER[effect.effect]
        std = _jackknife(effects, k, whole, model, j, dt)
        out.append(Finding(
            effect.effect, effect.target, dict(effect.parameters), {key: std},
            round(1.0 - chosen.p_values[k], 4), round(chosen.improvements[k], 4),
            f"the actuator position sensor {sensor} follows the command {effect.target} "
            f"through an {effect.effect.replace('_', ' ')} ({key} = "
            f"{effect.parameters[key]:.4g} {_unit(effect, model, j)}): it removes "
            f"{chosen.improvements[k]:.0%} of the held-out difference between them beyond "
            "the sensor's noise; judged on the sensor, not through the hull"))
    return effects, out


def _jackknife(effects: list[Effect], k: int, segments: Sequence[Segment], model: VehicleModel,
               j: int, dt: float) -> float:
    """Block jackknife standard deviation of effect ``k``'s parameter, the others held."""
    others = effects[:k] + effects[k + 1:]
    key = KEY_PARAMETER[effects[k].effect]
    values = []
    for b in range(BLOCKS):
        left_out = []
        for s in segments:
            cuts = np.linspace(0, len(s.position), BLOCKS + 1).astype(int)
            keep = np.ones(len(s.position), bool)
            keep[cuts[b]:cuts[b + 1]] = False
            left_out.append(Segment(s.commanded, s.position, keep))
        values.append(_fit(effects[k].effect, others, k, left_out, model, j, dt)[0]
                      .parameters[key])
    values = np.array(values)
    return float(np.sqrt((BLOCKS - 1) / BLOCKS * np.sum((values - values.mean()) ** 2)))


def _unit(effect: Effect, model: VehicleModel, j: int) -> str:
    unit = model.input_units[j]
    return {"input_gain": "", "input_delay": "s", "input_rate_limit": f"{unit}/s"}.get(
        effect.effect, unit)


def merged(diagnosis: Diagnosis, found: Sequence[Finding]) -> Diagnosis:
    """``diagnosis`` of the hull with the actuators' findings first: they are read off the
    actuator's own sensor, not inferred through the hull's dynamics and its sea."""
    if not found:
        return diagnosis
    hull = bool(diagnosis.findings)
    diagnosis.findings = [*found, *diagnosis.findings]
    if diagnosis.mismatch is None:
        diagnosis.reason = f"the hull cannot be judged: {diagnosis.reason}"
    diagnosis.mismatch = True
    diagnosis.fit["actuators"] = [{"effect": f.effect, "target": f.target,
                                   "improvement": f.improvement} for f in found]
    if not hull:
        diagnosis.fit["improvement"] = max(f.improvement for f in found)
        diagnosis.fit["validation"] = (
            "the actuators' findings: held-out last part of the record, fitted on the rest; "
            "the share of the difference between command and actuator position, beyond the "
            "sensor's noise, removed")
    return diagnosis
