"""Synthetic recordings: any vehicle model, plus any catalogue effects, under closed-loop control.

:func:`synthesize` simulates the "truth" (:class:`~marine_envs.models.effects.EffectModel`: the
nominal model plus effects) the way a sea trial is run: the environment's LQR design
(:func:`marine_envs.models.linear.dlqr`, on the task's own weights) holds the vehicle on a
reference that steps now and then, a random-step dither on every input keeps it excited, a
broadband sea drives the model's disturbance channels, and the sensors add white noise of a given
fraction of each channel's standard deviation. The controller acts on the true state (an ideal
observer), so it hides what the effects disturb exactly as a good autopilot would. The truth is
integrated by the project's one RK4 (:func:`marine_envs.models.integrate.rk4`), with time, since
an effect may switch on mid-record. The result is a :class:`~marine_envs.recording.Recording`
of the commanded inputs and the measured channels.

:func:`typical_effect` sizes an effect against a nominal run, so that one call makes a test case
of the same difficulty on every vehicle.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from marine_envs.envs import task_weights
from marine_envs.models import VehicleModel, get_model
from marine_envs.models.effects import (
    KEY_PARAMETER,
    ActuatorStream,
    Effect,
    EffectModel,
    resonator,
)
from marine_envs.models.integrate import rk4
from marine_envs.models.linear import dlqr, zoh
from marine_envs.recording import Recording
from marine_envs.sea.processes import GaussMarkov

from .residuals import displacements

DEG = math.pi / 180
#: A closed loop whose speeds or rates pass this (m/s, rad/s) has lost the vehicle.
LOST = 1e3
#: Broadband sea per model: (standard deviation per disturbance channel, correlation time, s).
SEA: dict[str, tuple[tuple[float, ...], float]] = {
    "usv": ((0.0003, 0.0003), 2.0),                     # wave moments, rad/s^2
    "hydrofoil": ((0.003, 0.003, 0.003, 0.003, 0.015, 0.015), 1.0),  # orbital speed, elevation,
                                                                      # surge
    "rov": ((0.05, 0.05, 0.01, 0.0), 60.0),             # current, m/s; no morph command
    "dp_vessel": ((1.0,) * 6, 0.0),                     # the model's own white-noise inputs
    "hovercraft": ((0.7, 0.7), 10.0),                   # wind gusts, m/s
}
#: Reference steps per model: the largest offset from the nominal state, by state.
REFERENCE: dict[str, dict[str, float]] = {
    "usv": {"psi": 15 * DEG},
    "hydrofoil": {"xi": 0.05, "theta": 1 * DEG},
    "rov": {"u": 0.3, "z": 1.0, "psi": 20 * DEG},
    "dp_vessel": {"north_lf": 5.0, "east_lf": 5.0, "psi_lf": 5 * DEG},
    "hovercraft": {"u": 2.0, "psi": 15 * DEG},
}
#: The dither's share of each input's half range (the hydrofoil's flaps stall beyond a little).
DITHER_SHARE = {"hydrofoil": 0.04}
DEFAULT_DITHER_SHARE = 0.15


def synthesize(model: str | VehicleModel, effects: Sequence[Effect] = (), *,
               duration: float = 300.0, dt: float = 0.1, noise: float = 0.05, seed: int = 0,
               measured: Sequence[str] | None = None, params: Mapping[str, float] | None = None,
               sea: float = 1.0, dither: float = 1.0, reference: float = 1.0,
               substeps: int = 4, disturbances: Sequence[str] = ()) -> Recording:
    """A closed-loop recording of ``model`` with ``effects`` added.

    :param model: model name or object (its parameters are the truth's, before the effects).
    :param effects: catalogue effects in the truth (see :mod:`marine_envs.models.effects`).
    :param duration: length, s.  :param dt: sample period, s.
    :param noise: sensor noise standard deviation as a fraction of each channel's standard
        deviation over the record.
    :param seed: seeds the sea, the references, the dither, the sensors and any wave forcing.
    :param measured: channels recorded (default: the model's usual sensors, or every state).
    :param params: parameter overrides of the nominal model.
    :param sea, dither, reference: scale the sea, the input dither and the reference steps.
    :param substeps: RK4 steps per sample.
    :param disturbances: disturbance channels recorded too (a wind or current sensor: the sea
        held over each sample, with the channels' relative sensor noise).
    :raises FloatingPointError: the closed loop loses the vehicle (a speed or rate beyond
        :data:`LOST`, or not finite): the effects are too strong for the autopilot.
    """
    vehicle = get_model(model) if isinstance(model, str) else model
    vehicle = vehicle.with_params(**(params or {}))
    truth = EffectModel(vehicle, effects)
    channels = tuple(measured or getattr(vehicle, "measured_names", vehicle.state_names))
    _check(vehicle, channels, duration, dt, noise)
    unknown = sorted(set(disturbances) - set(vehicle.disturbance_names))
    if unknown:
        raise ValueError(f"unknown disturbance(s) {unknown} for model {vehicle.name!r}; "
                         f"choose from {', '.join(vehicle.disturbance_names)}")
    rng = np.random.default_rng(seed)
    steps = int(round(duration / dt)) + 1
    time = np.arange(steps) * dt
    x_ref = _references(vehicle, steps, dt, reference, rng)
    commanded, states, d = _closed_loop(truth, x_ref, dt, sea, dither, substeps, rng, steps)
    outputs = vehicle.output(states) if vehicle.output_names != vehicle.state_names else states
    outputs = outputs[:, [vehicle.output_names.index(c) for c in channels]]
    spread = np.std(outputs, axis=0)
    measured_values = truth.measure(outputs, channels) \
        + noise * spread * rng.standard_normal(outputs.shape)
    d = d[:, [vehicle.disturbance_names.index(c) for c in disturbances]]
    d = d + noise * np.std(d, axis=0) * rng.standard_normal(d.shape)
    meta = {"generator": "estimators.diagnosis.synthetic", "seed": seed, "noise": noise, "dt": dt,
            "effects": [e.to_dict() for e in effects], "sea": sea, "dither": dither,
            "true_state": False}
    return Recording.from_arrays(vehicle.name, time, commanded,
                                 dict(zip(channels, measured_values.T, strict=True)),
                                 params=dict(params or {}), meta=meta,
                                 disturbances=dict(zip(disturbances, d.T, strict=True)))


def typical_effect(model: str, effect: str, target: str, *, strength: float = 0.3,
                   seed: int = 0, duration: float = 300.0, dt: float = 0.1,
                   against: str = "acceleration", **extra: Any) -> Effect:
    """An effect sized against a nominal run of the same vehicle, so that its term is about
    ``strength`` times the natural spread of the quantity it disturbs.

    State terms: ``strength`` times the standard deviation of ``x_dot[target]``; with
    ``against="model"``, of the nominal model's own ``x_dot[target]`` without the sea (for a
    vehicle whose accelerations are a near balance of large forces, such as the hydrofoil's
    foil lift against the sea's, the terms a model would get wrong). Input effects:
    a gain of ``1 - strength``, a delay of ``strength`` times 2 s (an actuator's dead time, the
    same on every vehicle), limits at ``2 * (1 - strength)`` standard deviations of the
    command, a dead zone of ``strength`` standard deviations, a rate limit at ``1 - strength``
    of the command's rate spread. A parameter change happens at 55 % of the record. ``extra``
    sets ``source``, ``expression``, ``what``, ``form`` or any parameter outright.
    """
    if against not in ("acceleration", "model"):
        raise ValueError(f"against={against!r}: size state terms against 'acceleration' or "
                         "'model'")
    vehicle = get_model(model)
    pilot = synthesize(vehicle, duration=duration, dt=dt, noise=0.0, seed=seed,
                       measured=vehicle.state_names)
    x, u = pilot.measurements, pilot.inputs
    names = vehicle.state_names
    spread = np.std(x, axis=0) + 1e-12
    if effect in ("input_gain", "input_delay", "input_saturation", "input_deadzone",
                  "input_rate_limit"):
        j = vehicle.input_names.index(target)
        c = u[:, j] - vehicle.u0[j]
        size = {"input_gain": {"k": 1 - strength},
                "input_delay": {"tau": round(strength * 2.0 / 0.1) * 0.1},
                "input_saturation": {"limit": 2 * (1 - strength) * np.std(c)},
                "input_deadzone": {"width": strength * np.std(c)},
                "input_rate_limit": {"rate": (1 - strength) * np.std(np.diff(c)) / dt}}[effect]
        return Effect(effect, target, {**size, **extra})
    if effect == "sensor_bias":
        k = vehicle.output_names.index(target)
        outputs = vehicle.output(x) if vehicle.output_names != names else x
        return Effect(effect, target, {"b": strength * float(np.std(outputs[:, k])), **extra})
    i = names.index(target)
    x_dot = vehicle.rhs(x, u) if against == "model" else np.gradient(x, dt, axis=0)
    rate = strength * float(np.std(x_dot[:, i]))
    source = extra.get("source", target)
    s = names.index(source) if source in names else i
    xi, xs = x[:, i], x[:, s]
    size = {
        "current": {"b": rate},
        "linear_damping": {"c": -rate / spread[i]},
        "quadratic_damping": {"c": -rate / np.std(xi * np.abs(xi))},
        "nonlinear_damping": {"c": -rate / np.std(xi**3), "form": "cubic"},
        "coupling": {"c": rate / spread[s]},
        "nonlinear_restoring": {"c": -rate / np.std(xs**3)},
        "parameter_change": {"time": round(0.55 * duration), "what": "damping",
                             "c": -2 * rate / spread[i]},
        "wave_frequency": {"omega": 1.0, "zeta": 0.05, "std": 2 * rate},
    }.get(effect)
    if effect == "unlisted":
        product = np.ones(len(x))
        for name in str(extra["expression"]).split("*"):
            column = x[:, names.index(name)] if name in names else \
                u[:, vehicle.input_names.index(name)]
            product = product * column
        size = {"c": rate / max(float(np.std(product)), 1e-12)}
    if size is None:
        raise ValueError(f"effect={effect!r} is not in the catalogue")
    if effect in ("coupling", "nonlinear_restoring"):
        size["source"] = source
    return Effect(effect, target, {**size, **extra})


def key_parameter(effect: Effect) -> float:
    """The number a diagnosis of ``effect`` must get right (``KEY_PARAMETER``)."""
    return float(effect.parameters[KEY_PARAMETER[effect.effect]])


# -- internals ------------------------------------------------------------------------------------
def _check(vehicle: VehicleModel, channels: Sequence[str], duration: float, dt: float,
           noise: float) -> None:
    unknown = sorted(set(channels) - set(vehicle.output_names))
    if unknown:
        raise ValueError(f"measured channel(s) {unknown} are not outputs of {vehicle.name!r}: "
                         f"{', '.join(vehicle.output_names)}")
    if not (math.isfinite(dt) and dt > 0 and math.isfinite(duration) and duration >= 2 * dt):
        raise ValueError(f"dt={dt!r} s and duration={duration!r} s must be > 0, duration >= 2 dt")
    if not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise={noise!r} must be >= 0 (a fraction of each channel's std)")


def _gain(vehicle: VehicleModel, dt: float) -> np.ndarray:
    """A discrete LQR gain at the nominal point; where a marginal mode is uncontrollable (no
    stabilising solution) a slightly discounted design, so one recipe serves every vehicle."""
    A, B, _ = vehicle.linearize()
    Ad, Bd = zoh(A, B, dt)
    q, r = task_weights(vehicle.name)  # the environment's task cost
    Q = np.diag([q.get(n, 0.0) for n in vehicle.state_names]) + 1e-6 * np.eye(len(A))
    R = np.diag([r[n] for n in vehicle.input_names])
    for discount in (1.0, 0.999, 0.99):
        try:
            return dlqr(Ad, Bd, Q, R, discount).K
        except ValueError:
            continue
    raise ValueError(f"no LQR design stabilises {vehicle.name!r} at its nominal point")


def _references(vehicle: VehicleModel, steps: int, dt: float, scale: float,
                rng: np.random.Generator) -> np.ndarray:
    """Nominal state plus random steps held 20-60 s in the model's reference states."""
    x_ref = np.tile(vehicle.x0, (steps, 1))
    for name, size in REFERENCE.get(vehicle.name, {}).items():
        i, k = vehicle.state_names.index(name), 0
        while k < steps:
            hold = int(rng.uniform(20, 60) / dt)
            x_ref[k:k + hold, i] += scale * size * rng.uniform(-1, 1)
            k += hold
    return x_ref


def _dither(vehicle: VehicleModel, steps: int, dt: float, scale: float,
            rng: np.random.Generator) -> np.ndarray:
    """Random steps held 1-4 s on every input, a share (``DITHER_SHARE``) of each half range."""
    low, high = vehicle.u_bounds
    out = np.zeros((steps, len(vehicle.input_names)))
    for j in range(out.shape[1]):
        k = 0
        while k < steps:
            hold = int(rng.uniform(1, 4) / dt)
            out[k:k + hold, j] = rng.uniform(-1, 1)
            k += hold
    share = DITHER_SHARE.get(vehicle.name, DEFAULT_DITHER_SHARE)
    return out * scale * share * (high - low) / 2


def _sea(vehicle: VehicleModel, steps: int, dt: float, scale: float,
         rng: np.random.Generator) -> np.ndarray:
    std, correlation = SEA.get(vehicle.name, ((0.0,) * len(vehicle.disturbance_names), 0.0))
    if correlation == 0.0:
        std = np.asarray(std) / math.sqrt(dt)  # unit-intensity white noise held over a step
    process = GaussMarkov(np.zeros(len(std)), scale * np.asarray(std), correlation, dt=dt)
    process.bind(1)
    process.reset(np.array([0]), [rng])
    return np.array([process.step()[0] for _ in range(steps)])


def _closed_loop(truth: EffectModel, x_ref: np.ndarray, dt: float, sea: float, dither: float,
                 substeps: int, rng: np.random.Generator,
                 steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Commanded inputs, true states and the sea ``(steps, n)`` of the closed loop."""
    vehicle = truth.model
    K = _gain(vehicle, dt)
    low, high = vehicle.u_bounds
    d = _sea(vehicle, steps, dt, sea, rng)
    probe = _dither(vehicle, steps, dt, dither, rng)
    forcing = {k: resonator(e.parameters["omega"], e.parameters["zeta"],
                            e.parameters.get("std", 1.0), steps, dt, rng)
               for k, e in enumerate(truth.effects) if e.effect == "wave_frequency"}
    actuator = ActuatorStream(vehicle, truth.effects, dt)
    rates = _rates(vehicle)
    x = vehicle.x0.copy()
    states, commanded = np.empty((steps, x.size)), np.empty((steps, len(vehicle.input_names)))
    h = dt / substeps
    for k in range(steps):
        states[k] = x
        u = np.clip(vehicle.u0 - K @ (x - x_ref[k]) + probe[k], low, high)
        commanded[k] = u
        applied = actuator.step(u)
        w = {e: f[k] for e, f in forcing.items()}
        def f(z, s, a=applied, dk=d[k], w=w):  # input and disturbance held over the step
            return truth.rhs(z, a, dk, s, w)

        x = rk4(f, x, h, substeps, t=k * dt)
        lost = ~np.isfinite(x) | (rates & (np.abs(x) >= LOST))
        if lost.any():
            i = int(np.argmax(lost))
            raise FloatingPointError(f"the simulated {vehicle.name} diverged at "
                                     f"t={(k + 1) * dt:.1f} s ({vehicle.state_names[i]} = "
                                     f"{x[i]:.3g}); the effects are too strong for the "
                                     "controller")
    return commanded, states, d


def _rates(vehicle: VehicleModel) -> np.ndarray:
    """Which states are speeds and rates: not positions or angles (which may grow with the
    distance run), nor the states of the model's own disturbance model."""
    kinematic = displacements(vehicle)
    return np.array([i not in kinematic and name not in vehicle.noise_model_states
                     for i, name in enumerate(vehicle.state_names)])
