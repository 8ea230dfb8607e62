"""A diagnosis checked on other tests (``marine validate``): does the corrected model predict
records it was not fitted on better than the nominal-calibrated one?

From a diagnosis JSON (:meth:`.result.Diagnosis.to_dict`) two models are rebuilt
(:func:`read_host`):

* **nominal-calibrated**: the host model with the nominal parameters the diagnosis started from
  (``params``) and the calibrated values (``calibration``), without the findings;
* **corrected**: the same with the values refitted with the findings
  (``calibration_quality.with_findings``) and the findings' terms (state terms in the equations,
  input effects on the inputs, sensor biases on the outputs).

Each record is predicted by both (:func:`validate`):

* **replayed**: the recorded inputs, free simulation from the record's first measured state;
* **re-run** as the manoeuvre the record shows: a zig-zag with the record's rudder amplitude A,
  heading check B, first direction, rudder rate and offset, reversed where the *predicted*
  heading reaches B (:func:`marine_envs.manoeuvres.read_zigzag` reads them off the record), or a
  turn at the record's steady rudder (:func:`~marine_envs.manoeuvres.read_turn`).

Compared with the record: the RMS error of every angle channel (heading, roll, deg) and the
standard criteria (zig-zag: first and second overshoot, time to check yaw; turn: the steady
turning rate), read off record and prediction by the same functions. A finding that states the
range of the states it was fitted over (``fitted_range``) is said to be used outside it when the
record or the corrected prediction goes beyond it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from marine_envs.manoeuvres import (
    HEADING_NAMES,
    RUDDER_NAMES,
    TurnCriteria,
    ZigzagCriteria,
    ZigzagRudder,
    read_turn,
    read_zigzag,
    wrap_angle,
)
from marine_envs.models import VehicleModel, get_model
from marine_envs.models.effects import (
    BatchActuators,
    Effect,
    EffectModel,
    applied_inputs,
    time_invariant,
)
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording, read_recording
from marine_envs.vessel import read_effects

from .output_error import Structure, _model_bandwidth
from .ranges import outside_range

#: The two models of a diagnosis, in the table's order.
MODELS = ("nominal-calibrated", "corrected")
#: The manoeuvres a record can be re-run as.
RERUNS = ("zigzag", "turn")


@dataclass(frozen=True)
class Host:
    """The models a diagnosis JSON rebuilds (:func:`read_host`)."""

    name: str  #: the host model's name
    models: dict[str, VehicleModel]  #: by :data:`MODELS`; the corrected one with its state terms
    input_effects: tuple[Effect, ...]  #: the corrected model's input effects
    output_effects: tuple[Effect, ...]  #: the corrected model's sensor biases
    #: the findings (JSON dicts) that say the range they were fitted over (``fitted_range``)
    ranged: tuple[Mapping[str, Any], ...] = ()

    def effects(self, model: str) -> tuple[tuple[Effect, ...], tuple[Effect, ...]]:
        """The input effects and sensor biases of ``model`` (none for the nominal)."""
        return ((), ()) if model == MODELS[0] else (self.input_effects, self.output_effects)


def read_host(document: Mapping[str, Any] | str | Path) -> Host:
    """The nominal-calibrated and corrected models of a diagnosis (module docstring).

    :param document: the diagnosis JSON, or its path.
    :raises ValueError: not a diagnosis (naming what is missing), an unknown model, a parameter
        the model does not have, or a finding that cannot be carried to another record.
    """
    where = "the diagnosis"
    if isinstance(document, str | Path):
        where = str(document)
        try:
            document = json.loads(Path(document).read_text())
        except OSError as error:
            raise ValueError(f"{where}: cannot read it: {error.strerror or error}") from None
        except json.JSONDecodeError as error:
            raise ValueError(f"{where}: not a diagnosis JSON (invalid JSON: {error})") from None
    missing = [k for k in ("model", "mismatch", "findings")
               if not isinstance(document, Mapping) or k not in document]
    if missing:
        raise ValueError(f"{where}: not a diagnosis JSON (written by 'marine diagnose "
                         f"--json'): no {', '.join(repr(k) for k in missing)}")
    base = get_model(str(document["model"]))
    try:
        nominal = {**document.get("params", {}), **document.get("calibration", {})}
        refitted = {n: q["value"] for n, q in document.get("calibration_quality", {})
                    .get("with_findings", {}).items()}
        effects = read_effects(document["findings"])
        calibrated = base.with_params(**nominal) if nominal else base
        final = calibrated.with_params(**refitted) if refitted else calibrated
        state = [e for e in effects if e.kind == "state"]
        corrected = EffectModel(final, time_invariant(state)) if state else final
        ranged = tuple(f for f in document["findings"] if f.get("fitted_range"))
    except (AttributeError, KeyError, TypeError, ValueError) as error:
        raise ValueError(f"{where}: cannot rebuild its models: {type(error).__name__} "
                         f"{error}") from None
    return Host(base.name, {MODELS[0]: calibrated, MODELS[1]: corrected},
                tuple(e for e in effects if e.kind == "input"),
                tuple(e for e in effects if e.kind == "output"), ranged)


def fitted_host(structure: Structure, theta: np.ndarray) -> Host:
    """The model of a free-simulation fit (its calibrated values, its terms at their fitted
    coefficients, its input effects) as a :class:`Host` whose two models are that one."""
    base, n = structure.series.model, len(structure.names)
    model = base.with_params(**{name: float(theta[k]) for k, name in
                                enumerate(structure.names)}) if n else base
    terms = [replace(t, parameters={**t.parameters, "b" if "b" in t.parameters else "c":
                                    float(theta[n + j])}) for j, t in enumerate(structure.terms)]
    state = [t for t in terms if t.kind == "state"]
    corrected = EffectModel(model, time_invariant(state)) if state else model
    return Host(base.name, dict.fromkeys(MODELS, corrected), tuple(structure.inputs),
                tuple(t for t in terms if t.kind == "output"))


def rerun_from_fit(structure: Structure, theta: np.ndarray, run: int) -> dict[str, float] | None:
    """Run ``run`` of a fit's series re-run as its zig-zag by the fitted model (as ``marine
    validate`` re-runs a record): RMS error per angle channel, rad; None when the run is no
    zig-zag or lacks the rudder or heading a re-run needs."""
    series, data = structure.series, structure.series.runs[run]
    host = fitted_host(structure, theta)
    rec = Recording.from_arrays(host.name, data.time, data.u,
                                {c: data.y[:, j] for j, c in enumerate(series.channels)},
                                meta={"name": data.name})
    try:
        check = _read(host, rec, "zigzag")
    except ValueError:
        return None
    return _rerun(host, MODELS[1], check, "zigzag").rms


# -- the results ----------------------------------------------------------------------------------
@dataclass
class Prediction:
    """One model's prediction of one record."""

    model: str  #: one of :data:`MODELS`
    mode: str  #: "replayed" or "re-run as a zigzag"/"re-run as a turn"
    time: np.ndarray  #: (T,) s, the record's clock
    angles: dict[str, np.ndarray]  #: predicted angle channels, rad
    rms: dict[str, float]  #: RMS error of each angle channel against the record, rad
    states: np.ndarray  #: (T, n_x) predicted states, model units
    criteria: ZigzagCriteria | TurnCriteria | None = None
    note: str = ""  #: why the criteria are missing


@dataclass
class RecordCheck:
    """A record, its criteria and both models' predictions of it."""

    name: str
    recording: Recording
    criteria: ZigzagCriteria | TurnCriteria | None
    predictions: list[Prediction] = field(default_factory=list)
    outside: list[str] = field(default_factory=list)  #: findings used outside their range


@dataclass
class Validation:
    """The answer of :func:`validate`: a table (:meth:`table`), its JSON and a figure."""

    host: Host
    rerun: str | None
    records: list[RecordCheck]

    def table(self) -> str:
        """The terminal table: per record and model, angle RMS (deg) and the criteria."""
        lines = []
        for check in self.records:
            lines.append(f"{check.name}: {_manoeuvre(check.criteria)}")
            channels = list(check.predictions[0].rms) if check.predictions else []
            head = "".join(f"{c + ' RMS':>11}" for c in channels) + _criteria_head(self.rerun)
            lines.append(f"  {'':<38}{head}")
            if check.criteria is not None:
                lines.append(f"  {'record':<38}{'':>{11 * len(channels)}}"
                             f"{_criteria_cells(check.criteria)}")
            for p in check.predictions:
                rms = "".join(f"{math.degrees(p.rms[c]):>7.2f} deg" for c in channels)
                cells = _criteria_cells(p.criteria) if p.mode != "replayed" else ""
                lines.append(f"  {p.model + ', ' + p.mode:<38}{rms}{cells}"
                             + (f"  ({p.note})" if p.note else ""))
            lines += [f"  warning: {line}" for line in check.outside]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """The table as JSON: angles in deg, times in s."""
        return {"model": self.host.name, "rerun": self.rerun, "records": [{
            "name": c.name, "criteria": _criteria_dict(c.criteria),
            "predictions": [{"model": p.model, "mode": p.mode,
                             "rms_deg": {k: math.degrees(v) for k, v in p.rms.items()},
                             "criteria": _criteria_dict(p.criteria)}
                            | ({"note": p.note} if p.note else {}) for p in c.predictions],
            "outside_fitted_range": c.outside} for c in self.records]}

    def plot(self, path: str | Path) -> Path:
        """Heading (or the first angle channel) per record: the record and every prediction,
        deg; saved with its provenance."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from marine_envs.provenance import save_figure

        fig, axes = plt.subplots(len(self.records), 1, figsize=(9, 2.8 * len(self.records)),
                                 squeeze=False)
        for ax, check in zip(axes[:, 0], self.records, strict=True):
            channel = next(iter(check.predictions[0].angles)) if check.predictions else None
            if channel is None:
                continue
            rec = check.recording
            ax.plot(rec.time, np.degrees(np.unwrap(rec.data[channel].to_numpy())), "k",
                    lw=1.5, label="record")
            for p in check.predictions:
                ax.plot(p.time, np.degrees(np.unwrap(p.angles[channel])),
                        "--" if p.mode == "replayed" else "-", lw=1,
                        color="C0" if p.model == MODELS[0] else "C3",
                        label=f"{p.model}, {p.mode}")
            ax.set_title(check.name, fontsize=9)
            ax.set_ylabel(f"{channel} (deg)")
            ax.legend(fontsize=7)
        axes[-1, 0].set_xlabel("time (s)")
        fig.tight_layout()
        out = save_figure(fig, path, dpi=110)
        plt.close(fig)
        return out


# -- the work -------------------------------------------------------------------------------------
def validate(diagnosis: Mapping[str, Any] | str | Path,
             recordings: Sequence[Recording | str | Path], rerun: str | None = None,
             progress: Callable[[int, int], None] | None = None) -> Validation:
    """Predict each record with the diagnosis's nominal-calibrated and corrected models
    (module docstring).

    :param diagnosis: the diagnosis JSON or its path.
    :param recordings: records of the same model (paths or :class:`Recording`).
    :param rerun: also re-run each record as a ``"zigzag"`` or a ``"turn"``; None: replay only.
    :param progress: called with (predictions done, their number), first with 0 once the inputs
        are checked.
    :raises ValueError: before any work: not a diagnosis, a record of another model, a record
        that does not show the manoeuvre (or lacks the rudder or heading it needs).
    """
    if rerun not in (None, *RERUNS):
        raise ValueError(f"rerun={rerun!r}: one of {', '.join(RERUNS)} or None")
    host = read_host(diagnosis)
    if not recordings:
        raise ValueError("no recording given")
    checks = [_read(host, r, rerun) for r in recordings]
    total, done = len(checks) * len(MODELS) * (2 if rerun else 1), 0
    if progress:
        progress(0, total)
    for check in checks:
        for model in MODELS:
            check.predictions.append(_replayed(host, model, check))
            done += 1
            if progress:
                progress(done, total)
            if rerun:
                check.predictions.append(_rerun(host, model, check, rerun))
                done += 1
                if progress:
                    progress(done, total)
        check.outside = _outside(host, check)
    return Validation(host, rerun, checks)


def _read(host: Host, source: Recording | str | Path, rerun: str | None) -> RecordCheck:
    """A record, checked for the model and the manoeuvre, with its criteria."""
    if isinstance(source, Recording):
        rec, name = source, str(source.meta.get("name", "recording"))
        if rec.model != host.name:
            raise ValueError(f"{name}: a recording of model {rec.model!r}, not of the "
                             f"diagnosis's {host.name!r}")
    else:
        rec, name = read_recording(source, model=host.name), Path(source).name
    rec = rec.filled() if rec.missing.any() else rec
    model = host.models[MODELS[0]]
    rudder, heading = _names(model, rec, name, rerun) if rerun else ("", "")
    if not _angle_channels(model, rec):
        raise ValueError(f"{name}: no angle channel (rad) of model {host.name!r} is measured: "
                         "nothing to compare")
    if rerun is None:
        return RecordCheck(name, rec, None)
    args = (rec.time, rec.data[heading].to_numpy(), rec.data[rudder].to_numpy())
    try:
        criteria = read_zigzag(*args) if rerun == "zigzag" else read_turn(*args)
    except ValueError as error:
        raise ValueError(f"{name}: cannot be re-run as a {rerun}: {error}") from None
    return RecordCheck(name, rec, criteria)


def _names(model: VehicleModel, rec: Recording, name: str, rerun: str) -> tuple[str, str]:
    """The rudder input and the measured heading a re-run needs; :raises ValueError: absent."""
    rudder = next((n for n in RUDDER_NAMES if n in model.input_names), None)
    heading = next((n for n in HEADING_NAMES if n in model.state_names
                    and n in rec.measured_names), None)
    if rudder is None or heading is None:
        lacks = " and ".join(w for w, n in (("a rudder input", rudder),
                                            ("a measured heading", heading)) if n is None)
        raise ValueError(f"{name}: --rerun {rerun} needs {lacks} ({' or '.join(RUDDER_NAMES)}"
                         f"; {' or '.join(HEADING_NAMES)}); model {model.name!r} records "
                         f"{', '.join(rec.measured_names)}")
    return rudder, heading


def _angle_channels(model: VehicleModel, rec: Recording) -> list[str]:
    units = dict(zip(model.output_names, model.output_units, strict=True))
    return [c for c in rec.measured_names if units.get(c) == "rad"]


def _first_state(model: VehicleModel, rec: Recording, k: int) -> np.ndarray:
    """The model's nominal state with every measured state taken from sample ``k``."""
    x = np.array(model.x0, dtype=float)
    for i, s in enumerate(model.state_names):
        if s in rec.measured_names:
            x[i] = float(rec.data[s].iloc[k])
    return x


def _disturbances(model: VehicleModel, rec: Recording) -> np.ndarray:
    """(T, n_d): the recorded disturbance columns, zero for the others."""
    d = np.zeros((len(rec.time), len(model.disturbance_names)))
    for j, name in enumerate(model.disturbance_names):
        if name in rec.disturbance_names:
            d[:, j] = rec.data[name].to_numpy()
    return d


def _substeps(model: VehicleModel, dt: float) -> int:
    """RK4 steps per sample: half a radian of the model's fastest mode per step at most (as
    the diagnosis's own free simulation, :class:`.output_error.Series`)."""
    base = model.nominal if isinstance(model, EffectModel) else model
    return max(1, math.ceil(_model_bandwidth(base, ()) * dt / 0.5))


def _replayed(host: Host, name: str, check: RecordCheck) -> Prediction:
    """Free simulation with the recorded inputs (through the model's input effects)."""
    model, rec = host.models[name], check.recording
    inputs_effects, _ = host.effects(name)
    u, dt = rec.inputs_for(model), rec.dt
    for effect in inputs_effects:
        u = applied_inputs(effect, model, u, dt)
    d, n = _disturbances(model, rec), _substeps(model, dt)
    x = _first_state(model, rec, 0)
    states = np.empty((len(rec.time), len(x)))
    with np.errstate(all="ignore"):
        for k in range(len(rec.time)):
            states[k] = x
            x = rk4(lambda z, _t, k=k: model.rhs(z, u[k], d[k]), x, dt / n, n)
    return _prediction(host, name, "replayed", check, rec.time, states)


def _rerun(host: Host, name: str, check: RecordCheck, rerun: str) -> Prediction:
    """The record's manoeuvre run closed loop by the model, from the record's state at its
    first execute (zig-zag) or first sample (turn)."""
    model, rec, c = host.models[name], check.recording, check.criteria
    rudder, heading = _names(model, rec, check.name, rerun)
    j, i_psi = model.input_names.index(rudder), model.state_names.index(heading)
    recorded = rec.data[rudder].to_numpy()
    start = c.start if isinstance(c, ZigzagCriteria) else 0
    x = _first_state(model, rec, start)
    if isinstance(c, ZigzagCriteria):
        law = ZigzagRudder(c.amplitude, c.switch, first_direction=c.first_direction,
                           turn_sign=c.turn_sign, rudder_rate=c.rudder_rate)
        # the rudder before the first execute (the sample at it has already moved)
        before = recorded[start - 1] - c.centre if start else 0.0
        law.reset(initial_heading=x[i_psi], initial_rudder=before)
        command = lambda k, z: c.centre + float(law(z[None, i_psi], rec.dt)[0])  # noqa: E731
    else:  # the recorded rudder until it has gone half way to the steady rudder, then held
        moved = np.abs(recorded - recorded[0]) >= 0.5 * abs(c.rudder - recorded[0])
        execute = int(np.argmax(moved))
        command = lambda k, z: recorded[k] if k < execute else c.rudder  # noqa: E731
    others = np.median(rec.inputs_for(model)[start:], axis=0)  # e.g. the propeller held
    states, rudders = _closed_loop(model, host.effects(name)[0], x, others, j, command,
                                   _disturbances(model, rec)[start:], rec.dt)
    time = rec.time[start:]
    prediction = _prediction(host, name, f"re-run as a {rerun}", check, time, states)
    try:
        read = read_zigzag if rerun == "zigzag" else read_turn
        prediction.criteria = read(time, states[:, i_psi], rudders)
    except ValueError as error:
        prediction.note = f"no {rerun} criteria: {error}"
    if not np.all(np.isfinite(states)):
        prediction.note = "diverged"
    return prediction


def _closed_loop(model: VehicleModel, input_effects: Sequence[Effect], x: np.ndarray,
                 inputs: np.ndarray, j: int, command: Callable[[int, np.ndarray], float],
                 d: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """States (T, n_x) and commanded rudder (T,) of ``command(k, x)`` on input ``j`` (the
    others held at ``inputs``), through the input effects at rest before the start."""
    actuators = BatchActuators(model, input_effects, dt)
    actuators.bind(1)
    n = _substeps(model, dt)
    states, rudders = np.empty((len(d), len(x))), np.empty(len(d))
    with np.errstate(all="ignore"):
        for k in range(len(d)):
            states[k] = x
            u = inputs.copy()
            u[j] = rudders[k] = command(k, x)
            applied = actuators.step(u[None])[0]
            x = rk4(lambda z, _t, k=k, a=applied: model.rhs(z, a, d[k]), x, dt / n, n)
    return states, rudders


def _prediction(host: Host, name: str, mode: str, check: RecordCheck, time: np.ndarray,
                states: np.ndarray) -> Prediction:
    """The angle channels of ``states`` (with the model's sensor biases) and their RMS error
    against the record over the same samples."""
    model, rec = host.models[name], check.recording
    outputs = np.asarray(model.output(states))
    rows = slice(len(rec.time) - len(time), None)
    angles, rms = {}, {}
    for channel in _angle_channels(model, rec):
        value = outputs[:, model.output_names.index(channel)].copy()
        value += sum(e.parameters["b"] for e in host.effects(name)[1] if e.target == channel)
        angles[channel] = value
        error = wrap_angle(value - rec.data[channel].to_numpy()[rows])
        rms[channel] = float(np.sqrt(np.mean(error**2)))
    return Prediction(name, mode, time, angles, rms, states)


def _outside(host: Host, check: RecordCheck) -> list[str]:
    """Each finding used beyond the range of a state it was fitted over, by the record or by
    the corrected model's predictions, in words (:func:`.ranges.outside_range`)."""
    model, rec = host.models[MODELS[1]], check.recording
    seen: dict[str, list[np.ndarray]] = {}
    for i, state in enumerate(model.state_names):
        seen[state] = [p.states[:, i] for p in check.predictions if p.model == MODELS[1]]
        if state in rec.measured_names:
            seen[state].append(rec.data[state].to_numpy())
    for name in rec.input_names:
        seen.setdefault(name, []).append(rec.data[name].to_numpy())
    units = dict(zip(model.state_names + model.input_names,
                     model.state_units + model.input_units, strict=True))
    here = {name: np.concatenate(values) for name, values in seen.items() if values}
    return [message for finding in host.ranged
            for message in outside_range(finding, here, units)]


def _display_unit(unit: str) -> tuple[str, float]:
    """Angles in degrees at the user's edge."""
    return ("deg" + unit[3:], 180 / math.pi) if unit.startswith("rad") else (unit, 1.0)


# -- the table's cells ----------------------------------------------------------------------------
def _manoeuvre(c: ZigzagCriteria | TurnCriteria | None) -> str:
    if isinstance(c, ZigzagCriteria):
        rate = "in one sample" if c.rudder_rate is None else \
            f"at {math.degrees(c.rudder_rate):.2g} deg/s"
        return (f"zig-zag {math.degrees(c.amplitude):.3g}/{math.degrees(c.switch):.3g} deg, "
                f"rudder {'positive' if c.first_direction > 0 else 'negative'} first, moved "
                f"{rate}, centred on {math.degrees(c.centre):.2f} deg")
    if isinstance(c, TurnCriteria):
        return f"turn at a steady rudder of {math.degrees(c.rudder):.3g} deg"
    return "replayed"


def _criteria_head(rerun: str | None) -> str:
    if rerun == "zigzag":
        return f"{'1st overshoot':>15}{'2nd overshoot':>15}{'check time':>12}"
    return f"{'turning rate':>15}" if rerun == "turn" else ""


def _criteria_cells(c: ZigzagCriteria | TurnCriteria | None) -> str:
    if isinstance(c, ZigzagCriteria):
        return (f"{c.first_overshoot_deg:>11.2f} deg{c.second_overshoot_deg:>11.2f} deg"
                f"{c.time_to_check_yaw:>10.1f} s")
    if isinstance(c, TurnCriteria):
        return f"{c.yaw_rate_deg:>9.3f} deg/s"
    return ""


def _criteria_dict(c: ZigzagCriteria | TurnCriteria | None) -> dict[str, Any] | None:
    if isinstance(c, ZigzagCriteria):
        return {"amplitude_deg": math.degrees(c.amplitude),
                "switch_deg": math.degrees(c.switch),
                "first_overshoot_deg": c.first_overshoot_deg,
                "second_overshoot_deg": c.second_overshoot_deg,
                "time_to_check_yaw_s": c.time_to_check_yaw,
                "initial_turning_time_s": c.initial_turning_time}
    if isinstance(c, TurnCriteria):
        return {"rudder_deg": math.degrees(c.rudder), "yaw_rate_deg_s": c.yaw_rate_deg}
    return None
