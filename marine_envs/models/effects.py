"""The catalogue of physics a vehicle model may leave out, as terms added to a model.

An :class:`Effect` names one catalogue entry, its ``target`` and its parameters; an
:class:`EffectModel` is a vehicle model with some effects added. The recording generator
(:mod:`estimators.diagnosis.synthetic`) simulates the truth with them, and the mismatch diagnosis
(:mod:`estimators.diagnosis`) fits them as hypotheses, so both mean exactly the same
thing.

============================ ====== ================================================= ==========
effect                       target term                                              parameters
============================ ====== ================================================= ==========
``current``                  state  ``+ b`` in the target's equation                   b
``linear_damping``           state  ``+ c * x_t``                                      c
``quadratic_damping``        state  ``+ c * x_t * abs(x_t)``                           c
``coupling``                 state  ``+ c * x_source``                                 source, c
``nonlinear_damping``        state  ``+ c * x_t**3``                                   c, form
``nonlinear_restoring``      state  ``+ c * x_source**3``                              source, c
``parameter_change``         state  from ``time`` on, ``+ c * x_t`` (what="damping")   time, c,
                                    or ``+ c`` (what="force")                          what
``wave_frequency``           state  ``+ w(t)``, narrow-band at ``omega``, ``zeta``      omega, zeta
``unlisted``                 state  ``+ c *`` a product of named states or inputs      expression, c
``input_gain``               input  applied = ``k * commanded``                        k
``input_delay``              input  applied = commanded ``tau`` seconds earlier        tau
``input_saturation``         input  applied = ``clip(commanded, -limit, limit)``       limit
``input_deadzone``           input  ``sign(u) * max(abs(u) - width, 0)``               width
``input_rate_limit``         input  slew limited to ``rate`` per second                rate
``sensor_bias``              output measured = true ``+ b``                            b
============================ ====== ================================================= ==========

Units are the model's SI units; a drag is a negative ``c``. Input effects act on the deviation of
the input from the model's nominal input ``u0`` (zero for centred actuators such as a rudder), so
that a trimmed actuator (a hovercraft's propeller pitch) saturates about its trim.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..compiled import Equations
from .base import VehicleModel
from .effect_terms import INPUT_CODES, INPUT_PARAMETER, STATE_CODES, actuate_boats, with_terms

FloatArray = NDArray[np.float64]

STATE_EFFECTS = ("current", "linear_damping", "quadratic_damping", "coupling",
                 "nonlinear_damping", "nonlinear_restoring", "parameter_change",
                 "wave_frequency", "unlisted")
INPUT_EFFECTS = ("input_gain", "input_delay", "input_saturation", "input_deadzone",
                 "input_rate_limit")
OUTPUT_EFFECTS = ("sensor_bias",)
#: Every catalogue entry, in the order of the issue's table.
CATALOGUE = ("current", "linear_damping", "quadratic_damping", "coupling", "input_gain",
             "input_delay", "input_saturation", "input_deadzone", "input_rate_limit",
             "wave_frequency", "parameter_change", "sensor_bias", "nonlinear_damping",
             "nonlinear_restoring", "unlisted")
#: The parameters each effect needs (numbers, except the strings named in TEXT_PARAMETERS).
REQUIRED = {
    "current": ("b",), "linear_damping": ("c",), "quadratic_damping": ("c",),
    "coupling": ("source", "c"), "nonlinear_damping": ("c",),
    "nonlinear_restoring": ("source", "c"), "parameter_change": ("time", "c"),
    "wave_frequency": ("omega", "zeta"), "unlisted": ("expression", "c"),
    "input_gain": ("k",), "input_delay": ("tau",), "input_saturation": ("limit",),
    "input_deadzone": ("width",), "input_rate_limit": ("rate",), "sensor_bias": ("b",),
}
TEXT_PARAMETERS = ("source", "form", "what", "expression")
#: The key number of each effect: what a diagnosis must get right.
KEY_PARAMETER = {"current": "b", "linear_damping": "c", "quadratic_damping": "c",
                 "coupling": "c", "nonlinear_damping": "c", "nonlinear_restoring": "c",
                 "parameter_change": "time", "wave_frequency": "omega", "unlisted": "c",
                 "input_gain": "k", "input_delay": "tau", "input_saturation": "limit",
                 "input_deadzone": "width", "input_rate_limit": "rate", "sensor_bias": "b"}


@dataclass(frozen=True)
class Effect:
    """One catalogue entry acting on one target.

    :param effect: name, one of :data:`CATALOGUE`.
    :param target: the state whose equation it enters, the input it distorts, or the measured
        channel it offsets (names as in the model).
    :param parameters: by name (see the module table), SI units; ``source``/``form``/``what``/
        ``expression`` are strings.
    """

    effect: str
    target: str
    parameters: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.effect not in CATALOGUE:
            raise ValueError(f"effect={self.effect!r} is not in the catalogue: "
                             f"{', '.join(CATALOGUE)}")
        missing = [p for p in REQUIRED[self.effect] if p not in self.parameters]
        if missing:
            raise ValueError(f"effect {self.effect!r} needs parameter(s) {missing}")
        for name, value in self.parameters.items():
            if name in TEXT_PARAMETERS:
                continue
            if not (isinstance(value, int | float | np.floating) and math.isfinite(value)):
                raise ValueError(f"{self.effect}: parameter {name}={value!r} must be a finite "
                                 "number")
        clean = {k: v if k in TEXT_PARAMETERS else float(v) for k, v in self.parameters.items()}
        object.__setattr__(self, "parameters", clean)

    @property
    def kind(self) -> str:
        """``"state"``, ``"input"`` or ``"output"``: where the effect acts."""
        if self.effect in INPUT_EFFECTS:
            return "input"
        return "output" if self.effect in OUTPUT_EFFECTS else "state"

    def check(self, model: VehicleModel) -> None:
        """:raises ValueError: the target (or source) is not a name of the model."""
        names = {"state": model.state_names, "input": model.input_names,
                 "output": model.output_names}[self.kind]
        if self.target not in names:
            raise ValueError(f"{self.effect}: target {self.target!r} is not one of the model's "
                             f"{self.kind}s {', '.join(names)}")
        source = self.parameters.get("source")
        if source is not None and source not in model.state_names:
            raise ValueError(f"{self.effect}: source {source!r} is not a state of "
                             f"{model.name!r}")
        if self.effect == "unlisted":
            factors(self.parameters["expression"], model)

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "target": self.target, "parameters": dict(self.parameters)}


def factors(expression: str, model: VehicleModel) -> list[tuple[str, int]]:
    """The factors of an ``unlisted`` product such as ``"r*phi"``: ``[("state", 1), ("state",
    4)]`` (kind and index). :raises ValueError: a factor that is not a state or input name."""
    out = []
    for name in expression.replace(" ", "").split("*"):
        if name in model.state_names:
            out.append(("state", model.state_names.index(name)))
        elif name in model.input_names:
            out.append(("input", model.input_names.index(name)))
        else:
            raise ValueError(f"unlisted: {name!r} in {expression!r} is neither a state nor an "
                             f"input of {model.name!r}")
    return out


# -- the terms -----------------------------------------------------------------------------------
def state_term(effect: Effect, model: VehicleModel, x: FloatArray, u: FloatArray,
               t: FloatArray | float, forcing: FloatArray | float = 0.0) -> FloatArray:
    """The addition to ``x_dot[target]`` of a state effect, shape ``x.shape[:-1]``.

    :param x, u: states and (applied) inputs, ``(..., n_x)`` and ``(..., n_u)``.
    :param t: time, s (``parameter_change``).
    :param forcing: the narrow-band process ``w(t)`` of ``wave_frequency``.
    """
    p, name = effect.parameters, effect.effect
    xt = x[..., model.state_names.index(effect.target)]
    if name == "current":
        return np.full(xt.shape, float(p["b"]))
    if name == "linear_damping":
        return p["c"] * xt
    if name == "quadratic_damping":
        return p["c"] * xt * np.abs(xt)
    if name == "nonlinear_damping":
        return p["c"] * xt**3
    if name in ("coupling", "nonlinear_restoring"):
        xs = x[..., model.state_names.index(p["source"])]
        return p["c"] * (xs if name == "coupling" else xs**3)
    if name == "parameter_change":
        after = np.asarray(t) >= p["time"]
        change = xt if p.get("what", "damping") == "damping" else 1.0
        return np.where(after, p["c"] * change, 0.0)
    if name == "wave_frequency":
        return np.broadcast_to(np.asarray(forcing, dtype=float), xt.shape)
    if name == "unlisted":
        value = np.asarray(p["c"], dtype=float)
        for kind, i in factors(p["expression"], model):
            value = value * (x[..., i] if kind == "state" else u[..., i])
        return value
    raise ValueError(f"{name!r} is not a state effect")


def applied_inputs(effect: Effect, model: VehicleModel, commanded: ArrayLike,
                   dt: float) -> FloatArray:
    """The inputs the vehicle receives when an input effect distorts the ``commanded`` sequence
    ``(T, n_u)`` sampled every ``dt`` s (held between samples)."""
    u = np.array(commanded, dtype=float)
    j = model.input_names.index(effect.target)
    u0 = float(model.u0[j])
    c = u[:, j] - u0
    p = effect.parameters
    if effect.effect == "input_gain":
        a = p["k"] * c
    elif effect.effect == "input_delay":
        a = delayed(c, p["tau"] / dt)
    elif effect.effect == "input_saturation":
        a = np.clip(c, -p["limit"], p["limit"])
    elif effect.effect == "input_deadzone":
        a = np.sign(c) * np.maximum(np.abs(c) - p["width"], 0.0)
    elif effect.effect == "input_rate_limit":
        a = rate_limited(c, p["rate"] * dt)
    else:
        raise ValueError(f"{effect.effect!r} is not an input effect")
    u[:, j] = u0 + a
    return u


def delayed(signal: FloatArray, steps: float) -> FloatArray:
    """``signal`` delayed by a (fractional, >= 0) number of samples, linearly interpolated; the
    first value is held before the start."""
    k = np.arange(len(signal)) - max(float(steps), 0.0)
    return np.interp(k, np.arange(len(signal)), signal)


def rate_limited(signal: FloatArray, max_step: float) -> FloatArray:
    """``signal`` with each sample-to-sample change clipped to ``+-max_step``."""
    out = np.empty_like(signal)
    value = signal[0]
    for k, target in enumerate(signal.tolist()):
        value += min(max(target - value, -max_step), max_step)
        out[k] = value
    return out


def resonator(omega: float, zeta: float, std: float, n: int, dt: float,
              rng: np.random.Generator) -> FloatArray:
    """``n`` samples of a stationary narrow-band process: white noise through
    ``omega^2 / (s^2 + 2 zeta omega s + omega^2)``, scaled to standard deviation ``std``."""
    from scipy import signal

    system = signal.cont2discrete(([omega**2], [1.0, 2 * zeta * omega, omega**2]), dt)
    b, a = np.ravel(system[0]), system[1]
    burn = int(10 / (zeta * omega * dt)) + 1
    w = signal.lfilter(b, a, rng.standard_normal(n + burn))[burn:]
    return w * (std / max(float(np.std(w)), 1e-300))


# -- a model with effects -------------------------------------------------------------------------
def term_table(effects: Sequence[Effect], model: VehicleModel) -> FloatArray:
    """The state terms of ``effects`` (time-invariant ones) as the table the compiled
    :func:`~marine_envs.models.effect_terms.add_terms` reads: per term ``code, target,
    coefficient, n, operands...``, an operand a state index ``i`` or an input as ``-(j + 1)``;
    then the table's length."""
    table: list[float] = []
    for effect in effects:
        p, names = effect.parameters, model.state_names
        if effect.effect == "unlisted":
            operands = [i if kind == "state" else -(i + 1)
                        for kind, i in factors(p["expression"], model)]
        elif effect.effect in ("coupling", "nonlinear_restoring"):
            operands = [names.index(p["source"])]
        else:
            operands = [names.index(effect.target)]
        coefficient = p["b"] if effect.effect == "current" else p["c"]
        table += [STATE_CODES[effect.effect], names.index(effect.target), coefficient,
                  len(operands), *operands]
    return np.array([*table, len(table)], dtype=float)


def input_table(effects: Sequence[Effect], model: VehicleModel, dt: float
                ) -> tuple[np.ndarray, np.ndarray, FloatArray, FloatArray, np.ndarray]:
    """The input effects as the compiled :func:`~marine_envs.models.effect_terms.actuate` reads
    them: codes, input indices, nominal inputs, parameters (a delay in samples, a rate limit per
    sample) and delay-line lengths (the samples a delay interpolates over)."""
    kinds = np.array([INPUT_CODES[e.effect] for e in effects], dtype=np.int64)
    inputs = np.array([model.input_names.index(e.target) for e in effects], dtype=np.int64)
    u0 = np.array([float(model.u0[j]) for j in inputs.tolist()])
    values = []
    for e in effects:
        value = e.parameters[INPUT_PARAMETER[e.effect]]
        values.append(value / dt if e.effect == "input_delay" else
                      value * dt if e.effect == "input_rate_limit" else value)
    lengths = np.array([int(e.parameters["tau"] / dt) + 3 if e.effect == "input_delay" else 1
                        for e in effects], dtype=np.int64)
    return kinds, inputs, u0, np.array(values, dtype=float), lengths


def time_invariant(effects: Sequence[Effect]) -> list[Effect]:
    """``effects`` when each is a time-invariant state effect (one that enters a model's
    equations for good: not ``wave_frequency``, whose forcing is a process of its own, nor
    ``parameter_change``). :raises ValueError: another kind of effect, naming it."""
    for effect in effects:
        if effect.kind != "state" or effect.effect in ("wave_frequency", "parameter_change"):
            raise ValueError(f"{effect.effect}: only time-invariant state effects enter "
                             "a model's equations")
    return list(effects)


class EffectModel(VehicleModel):
    """A vehicle model with catalogue effects added: a model of its own (the nominal one's
    names, units, bounds and outputs) whose equations carry the state effects, and which knows
    its input effects (:meth:`applied_inputs`) and sensor biases (:meth:`measure`).

    With compiled nominal equations and time-invariant state terms its equations are compiled
    too (:func:`~marine_envs.models.effect_terms.with_terms`: the nominal ones plus the terms,
    tabled after the nominal constants), so an environment steps it in its compiled kernel and
    :meth:`rhs` runs the same code; else :meth:`rhs` adds :func:`state_term` in numpy (with time
    and forcing for ``parameter_change`` and ``wave_frequency``).

    :param model: the nominal model.
    :param effects: the effects; at most one per (effect, target) pair.
    :raises ValueError: a target (or source) the model does not have.
    """

    def __init__(self, model: VehicleModel, effects: Sequence[Effect] = ()) -> None:
        for effect in effects:
            effect.check(model)
        super().__init__(model.params)
        self.nominal, self.effects = model, tuple(effects)
        for attr in ("name", "state_names", "input_names", "disturbance_names", "state_units",
                     "input_units", "disturbance_units", "wave_disturbances"):
            setattr(self, attr, getattr(model, attr))
        self.state_effects = [e for e in self.effects if e.kind == "state"]
        self.input_effects = [e for e in self.effects if e.kind == "input"]
        self.output_effects = [e for e in self.effects if e.kind == "output"]
        self.equations = self._compiled_equations()

    #: The nominal model (the name the diagnosis's simulations use).
    model = property(lambda self: self.nominal)
    x0 = property(lambda self: self.nominal.x0)
    u0 = property(lambda self: self.nominal.u0)
    u_bounds = property(lambda self: self.nominal.u_bounds)
    output_names = property(lambda self: self.nominal.output_names)
    output_units = property(lambda self: self.nominal.output_units)

    def _compiled_equations(self) -> Equations | None:
        """The nominal equations plus the state terms, or None when either is numpy only."""
        nominal = self.nominal
        if not equations_of(nominal) or np.ndim(nominal.constants) != 1:
            return None
        if any(e.effect not in STATE_CODES for e in self.state_effects):
            return None
        return with_terms(nominal.equations) if self.state_effects else nominal.equations

    def pack(self) -> FloatArray:
        """The nominal constants, then the state terms' table (:func:`term_table`)."""
        constants = self.nominal.constants
        if not self.state_effects:
            return constants
        return np.concatenate([constants, term_table(self.state_effects, self.nominal)])

    def output(self, x: FloatArray) -> FloatArray:
        return self.nominal.output(x)

    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None, t: float = 0.0,
            forcing: Mapping[int, float] | None = None) -> FloatArray:
        """``x_dot`` of the nominal model plus every state effect (``u`` is the applied input;
        ``t`` the time, s; ``forcing`` maps the index in :attr:`effects` of a
        ``wave_frequency`` effect to the current value of its narrow-band process)."""
        if self.equations is not None:
            return super().rhs(x, u, d)
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        x_dot = self.nominal.rhs(x, u, d)
        for k, effect in enumerate(self.effects):
            if effect.kind == "state":
                i = self.nominal.state_names.index(effect.target)
                w = (forcing or {}).get(k, 0.0)
                x_dot[..., i] += state_term(effect, self.nominal, x, u, t, w)
        return x_dot

    def with_params(self, **changes: float) -> EffectModel:
        return EffectModel(self.nominal.with_params(**changes), self.effects)

    def applied_inputs(self, commanded: ArrayLike, dt: float) -> FloatArray:
        """The applied input sequence ``(T, n_u)`` for a commanded one (held samples)."""
        u = np.asarray(commanded, dtype=float)
        for effect in self.input_effects:
            u = applied_inputs(effect, self.nominal, u, dt)
        return u

    def measure(self, outputs: FloatArray, names: Sequence[str]) -> FloatArray:
        """Outputs ``(..., len(names))`` (channels ``names``) plus every sensor bias."""
        out = np.array(outputs, dtype=float)
        for effect in self.output_effects:
            if effect.target in names:
                out[..., list(names).index(effect.target)] += effect.parameters["b"]
        return out


def equations_of(model: VehicleModel) -> bool:
    """True when ``model.rhs`` runs its compiled
    :attr:`~marine_envs.models.base.VehicleModel.equations` (so a step kernel may integrate
    them instead)."""
    if model.equations is None:
        return False
    return isinstance(model, EffectModel) or type(model).rhs is VehicleModel.rhs


class BatchActuators:
    """Input effects applied to a batch of boats one control period at a time, each boat with
    its own delay lines and rate-limited positions (arrays the step kernel shares); the
    arithmetic is :func:`~marine_envs.models.effect_terms.actuate`.

    :param at_rest: a boat starts with its actuators at the nominal input (a rate-limited one
        moves from there, a delay line is full of it); else at its first command.
    """

    def __init__(self, model: VehicleModel, effects: Sequence[Effect], dt: float,
                 at_rest: bool = True) -> None:
        for effect in effects:
            effect.check(model)
        self.model, self.dt, self.at_rest = model, dt, at_rest
        self.effects = [e for e in effects if e.kind == "input"]
        #: codes, inputs, nominal inputs, parameters, delay-line lengths (:func:`input_table`)
        self.table = input_table(self.effects, model, dt)

    def bind(self, batch_size: int) -> None:
        n, length = len(self.effects), int(max(self.table[4], default=1))
        self.line = np.zeros((batch_size, n, length))
        self.count = np.zeros((batch_size, n), dtype=np.int64)
        self.previous = np.zeros((batch_size, n))
        self.boats = np.arange(batch_size, dtype=np.int64)
        self.reset(self.boats)

    def reset(self, idx: ArrayLike) -> None:
        """Boats ``idx`` start again (in place: the step kernel holds these arrays)."""
        self.line[idx], self.previous[idx] = 0.0, 0.0
        self.count[idx] = self.table[4] if self.at_rest else 0

    def step(self, commanded: FloatArray) -> FloatArray:
        """The applied inputs ``(batch, n_u)`` for the commanded ones."""
        u = np.array(commanded, dtype=float, order="C")
        actuate_boats(*self.table, self.line, self.count, self.previous, self.boats, u)
        return u


class ActuatorStream:
    """The input effects of one vehicle applied one sample at a time from its first command,
    for closed-loop simulation (a :class:`BatchActuators` of one boat): equal to
    :func:`applied_inputs` over the whole sequence, effect after effect."""

    def __init__(self, model: VehicleModel, effects: Sequence[Effect], dt: float) -> None:
        self.batch = BatchActuators(model, effects, dt, at_rest=False)
        self.batch.bind(1)

    def step(self, commanded: ArrayLike) -> FloatArray:
        """The applied input ``(n_u,)`` for this sample's command."""
        return self.batch.step(np.asarray(commanded, dtype=float)[None, :])[0]
