"""The batched simulation core behind every environment: model + sea + sensors + task.

One :class:`Simulator` steps a batch of independent boats with array operations. The single
environment is a batch of one, the native vector environment a batch of N, so both run the same
code and a vector environment equals N single ones given the same seeds.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal, TypedDict

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models import VehicleModel
from ..models.effects import BatchActuators, Effect, EffectModel, time_invariant
from ..models.integrate import ExactStep, RK4Step
from ..sea.processes import DisturbanceSource
from ..sensors import SensorSuite, as_index, per_channel
from .kernel import CompiledStep, StepPlan, all_finite
from .stages import RowsStep, cost_rows, limit_rows
from .system import Actuation, InitialState, Task

FloatArray = NDArray[np.float64]


def make_task(model: VehicleModel, weights: Mapping[str, float], input_weights: Mapping[str, float],
              *, reference: Mapping[str, float] | None = None,
              limits: Mapping[str, float | tuple[float, float]] | None = None,
              reward_scale: float = 1.0) -> Task:
    """A :class:`~marine_envs.envs.system.Task` from weights, reference and limits given by
    state and input name.

    :param reference: offsets from the model's nominal state ``x0``, by state name.
    :param limits: per state, ``a`` for ``|x| <= a`` or ``(low, high)``; the episode ends outside.
    """
    names = model.state_names
    q = per_channel("state_weights", weights, names)
    r = per_channel("input_weights", input_weights, model.input_names)
    if not (np.all(q >= 0) and np.all(r >= 0) and np.isfinite(q).all() and np.isfinite(r).all()):
        raise ValueError(f"state_weights={q.tolist()} / input_weights={r.tolist()} must be >= 0")
    pairs = {k: (-v, v) if np.isscalar(v) else tuple(v) for k, v in (limits or {}).items()}
    low = per_channel("limits", {k: lo for k, (lo, _) in pairs.items()}, names, -math.inf)
    high = per_channel("limits", {k: hi for k, (_, hi) in pairs.items()}, names, math.inf)
    if not np.all(low < high):
        raise ValueError(f"limits={limits!r} is invalid: each needs low < high (or a > 0)")
    return Task(q=q, r=r, x_ref=model.x0 + per_channel("reference", reference, names),
                u_ref=model.u0, low=low, high=high, reward_scale=reward_scale)


class SensorOptions(TypedDict, total=False):
    """Sensor settings every environment accepts: per channel, a number for all channels or
    ``{channel: value}``, SI units (see :meth:`SensorSuite.standard`).

    A setting left out is the environment's default. None turns the stage off: no noise, no bias,
    no quantization, no full scale, a sample every control step, no delay, no dropout. A mapping
    sets the channels it names; a channel it leaves out, or maps to None, has the stage off
    (``quantization={"psi": None}`` and ``quantization={}`` quantize no channel)."""

    noise_std: float | Mapping[str, float] | None
    bias: float | Mapping[str, float] | None
    quantization: float | Mapping[str, float] | None
    sensor_range: float | Mapping[str, float] | None
    sample_period: int | Mapping[str, int] | None
    delay: int | Mapping[str, int] | None
    dropout: float | Mapping[str, float] | None


def make_sensors(channels: Sequence[str], defaults: Mapping[str, Any],
                 options: Mapping[str, Any], **fixed: Any) -> SensorSuite:
    """An environment's sensor suite: each :class:`SensorOptions` setting from ``options`` when
    the user gave it (None too: it turns the stage off), else from the environment's
    ``defaults``.

    :param options: the environment's remaining keyword arguments; any other name is an error.
    :param fixed: further arguments of :meth:`SensorSuite.standard` (``wrap``, ``quantizer``).
    :raises ValueError: an unknown argument, naming it.
    """
    unknown = sorted(set(options) - set(SensorOptions.__annotations__))
    if unknown:
        raise ValueError(f"unknown argument(s) {unknown}; see the environment's docstring")
    chosen = {k: options[k] if k in options else defaults.get(k)
              for k in SensorOptions.__annotations__}
    return SensorSuite.standard(channels, **chosen, **fixed)


def uniform_initial_state(model: VehicleModel, spread: Mapping[str, float],
                          centre: ArrayLike | None = None) -> InitialState:
    """Initial states uniform within ``centre +- spread`` (default centre: the nominal state)."""
    half_width = per_channel("initial_spread", spread, model.state_names)
    if not np.all(np.isfinite(half_width) & (half_width >= 0)):
        raise ValueError(f"initial_spread={dict(spread)!r} is invalid: half-widths >= 0")
    middle = model.x0 if centre is None else np.asarray(centre, dtype=float)
    return UniformInitialState(middle, half_width)



@dataclasses.dataclass(frozen=True, eq=False)
class UniformInitialState:
    """Initial states uniform within ``middle +- half_width`` (state units); a class, not a
    closure, so that an environment pickles."""

    middle: FloatArray
    half_width: FloatArray

    def __call__(self, rng: np.random.Generator) -> FloatArray:
        return self.middle + self.half_width * rng.uniform(-1.0, 1.0, self.half_width.size)

    def batch(self, rngs: Sequence[np.random.Generator]) -> FloatArray:
        """One initial state per generator (boats x states): each boat's draws from its own
        generator, scaled in one operation (the numbers of calling it boat by boat)."""
        draws = np.empty((len(rngs), self.half_width.size))
        for row, rng in zip(draws, rngs, strict=True):
            row[:] = rng.uniform(-1.0, 1.0, self.half_width.size)
        return self.middle + self.half_width * draws


#: RK4's stability limit on the real axis: ``|lambda| h`` beyond it grows every step.
RK4_STABILITY = 2.78


def _check_rk4_stable(model: VehicleModel, dt: float, substeps: int) -> None:
    """:raises ValueError: RK4 steps of ``dt / substeps`` s are unstable for the fastest mode
    of ``model`` linearised at its nominal point (the run would diverge)."""
    A, _, _ = model.linearize()
    fastest = float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
    if fastest * dt / substeps > RK4_STABILITY:
        limit = RK4_STABILITY * substeps / fastest
        raise ValueError(f"dt={dt!r} is invalid: RK4 with {substeps} substep(s) is unstable for "
                         f"the {model.name} model's fastest mode ({fastest:.3g} 1/s) above "
                         f"dt = {limit:.3g} s (the run would diverge)")


class Simulator:
    """Steps a batch of boats: disturbances -> dynamics -> cost -> sensors.

    :meth:`step` runs a control period of every boat in one compiled call
    (:class:`~marine_envs.envs.kernel.CompiledStep`, effects included) when the model has
    compiled equations (or is stepped exactly) and the sensors are the standard chain; else,
    and always through :meth:`apply`, :meth:`advance` and :meth:`measure`, stage by stage over
    the batch (a zig-zag rudder law, user models): the same compiled stages
    (:mod:`~marine_envs.envs.stages`) run over the rows, only a user model's numpy equations
    and sensor stages of other kinds in numpy. Both give the same numbers.

    :param model: the vehicle model.
    :param sensors: the sensor chain over some of the model's states (by name).
    :param task: cost and termination.
    :param disturbances: the source of the model's disturbance inputs (a wave realisation,
        :mod:`~marine_envs.sea.processes`, or several stacked), or None for none.
    :param dt: control period, s.
    :param initial_state: draws one boat's initial state from its generator.
    :param integrator: ``"exact"`` (linear models only) or ``"rk4"``.
    :param substeps: RK4 steps per control period.
    :param disturbance_seed: if set, every episode sees the same disturbance realisation (the
        same sea); sensor noise and initial states still vary.
    :param actuation: how actions become inputs; default: directly, over the model's bounds.
    """

    def __init__(self, model: VehicleModel, sensors: SensorSuite, task: Task,
                 disturbances: DisturbanceSource | None, dt: float,
                 initial_state: InitialState, integrator: Literal["exact", "rk4"] = "exact",
                 substeps: int = 4, disturbance_seed: int | None = None,
                 actuation: Actuation | None = None) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: the control period must be > 0 s")
        if integrator == "exact" and not model.is_linear:
            raise ValueError(f"integrator='exact' needs a linear model; {model.name!r} is not")
        if integrator not in ("exact", "rk4"):
            raise ValueError(f"integrator={integrator!r} is invalid: 'exact' or 'rk4'")
        if not (isinstance(substeps, int) and substeps >= 1):
            raise ValueError(f"substeps={substeps!r} is invalid: an integer >= 1")
        if integrator == "rk4":
            _check_rk4_stable(model, dt, substeps)
        unknown = sorted(set(sensors.channels) - set(model.output_names))
        if unknown:
            raise ValueError(f"sensor channel(s) {unknown} are not outputs of model "
                             f"{model.name!r}: {', '.join(model.output_names)}")
        self.model, self.sensors, self.task = model, sensors, task
        self.effects: tuple[Effect, ...] = ()
        self.actuators: BatchActuators | None = None
        self.bias = np.zeros(len(sensors.channels))  # the sensor-bias effects, channel units
        self.disturbances, self.disturbance_seed = disturbances, disturbance_seed
        self.dt, self.initial_state = dt, initial_state
        self.integrate = ExactStep(model, dt) if integrator == "exact" else RK4Step(model, dt,
                                                                                    substeps)
        self._outputs_are_states = model.output_names == model.state_names
        self.measured = as_index(np.array([model.output_names.index(c)
                                           for c in sensors.channels]))
        self.actuation = Actuation.direct(model) if actuation is None else actuation
        self.n_actions = len(self.actuation.names)
        # the action map's (1, n) arrays, as the step kernel reads them
        self.u_scale, self.u_mid = self.actuation.u_scale, self.actuation.u_mid
        self._allocation = self.actuation.allocation
        limited = np.flatnonzero(np.isfinite(task.low) | np.isfinite(task.high))
        self._limited_list = limited.astype(np.int64)
        self._low, self._high = task.low[limited][None, :], task.high[limited][None, :]
        n_d = len(model.disturbance_names)
        # the reward is a weighted sum of squares of the stacked [x u d] vector
        self._weights = -task.reward_scale * np.concatenate([task.q, task.r, np.zeros(n_d)])
        reference = np.concatenate([task.x_ref, task.u_ref, np.zeros(n_d)])
        self._reference = reference

    def add_effects(self, effects: Sequence[Effect]) -> None:
        """Physics the nominal model leaves out (a diagnosis's findings): state effects enter
        the equations (stepped by RK4 from then on), input effects sit between the action and
        the model, sensor biases offset the measured channels. Call before :meth:`bind`."""
        state = [e for e in effects if e.kind == "state"]
        for effect in state:
            effect.check(self.model)
        if time_invariant(state):
            self.model = EffectModel(self.model, state)
            substeps = getattr(self.integrate, "substeps", 4)
            self.integrate = RK4Step(self.model, self.dt, substeps)
        inputs = [e for e in effects if e.kind == "input"]
        self.actuators = BatchActuators(self.model, inputs, self.dt) if inputs else None
        self.bias = np.zeros(len(self.sensors.channels))
        for effect in effects:
            if effect.kind == "output":
                effect.check(self.model)
                if effect.target not in self.sensors.channels:
                    raise ValueError(f"sensor_bias: {effect.target!r} is not a measured "
                                     f"channel: {', '.join(self.sensors.channels)}")
                self.bias[self.sensors.channels.index(effect.target)] += effect.parameters["b"]
        self.effects = tuple(effects)

    def bind(self, batch_size: int) -> None:
        """Allocate state for ``batch_size`` boats."""
        self.batch_size = batch_size
        self.x = np.tile(self.model.x0, (batch_size, 1))
        self.u = self._commanded = np.tile(self.model.u0, (batch_size, 1))
        self.d = np.zeros((batch_size, len(self.model.disturbance_names)))
        self.clipped = np.zeros(batch_size, dtype=bool)
        self.steps = np.zeros(batch_size, dtype=np.int64)
        self._one = np.ones(1, dtype=np.int64)
        self.sensors.bind(batch_size)
        if self.disturbances is not None:
            self.disturbances.bind(batch_size)
        if self.actuators is not None:
            self.actuators.bind(batch_size)
        # the numpy path's integration: the compiled one-boat step over the rows, where there is one
        self._step_rows = RowsStep.of(self.model, self.integrate, self.dt)
        self._compiled = self._compile()

    def _compile(self) -> CompiledStep | None:
        """The compiled path of this bound simulator, or None (steps of its own, in a subclass;
        a model or sensors the kernel does not know: :meth:`CompiledStep.of`)."""
        own_steps = (type(self).apply, type(self).advance, type(self).measure) != \
            (Simulator.apply, Simulator.advance, Simulator.measure)
        if own_steps:
            return None
        return CompiledStep.of(StepPlan(
            model=self.model, integrate=self.integrate, dt=self.dt, sensors=self.sensors,
            batch_size=self.batch_size, mid=self.u_mid[0], scale=self.u_scale[0],
            allocation=self._allocation, weights=self._weights, reference=self._reference,
            limited=self._limited_list, low=self._low[0], high=self._high[0], steps=self.steps,
            disturbances=self.disturbances, actuators=self.actuators, output_bias=self.bias))

    @property
    def u_commanded(self) -> FloatArray:
        """The physical inputs the actions commanded (batch x inputs): clipped and scaled to
        the model's input units, before any actuator effect; :attr:`u` is what the actuators
        applied (the same array when there are none)."""
        return self.u if self.actuators is None else self._commanded

    @property
    def compiled(self) -> bool:
        """True when :meth:`step` runs the compiled kernel (else numpy)."""
        return self._compiled is not None

    def run_in_numpy(self) -> None:
        """Step every boat through :meth:`apply`, :meth:`advance` and :meth:`measure` in numpy
        from now on (the reference the kernel is tested against; slower)."""
        if self._compiled is not None:
            for stream in self._compiled.streams():
                stream.recount()  # the kernel moves the cursors without counting
        self._compiled = None

    def step(self, action: ArrayLike, measure: bool = True
             ) -> tuple[FloatArray | None, FloatArray, NDArray[np.bool_]]:
        """One control period of every boat: :meth:`apply` the actions, :meth:`advance` and,
        if ``measure``, :meth:`measure`; in one compiled call where the kernel runs.

        :return: ``(measurements or None, reward, failed)``.
        :raises ValueError: NaN or inf in the action, or a wrong shape (nothing changed).
        :raises FloatingPointError: a boat's state became NaN or inf.
        """
        if self._compiled is not None:
            return self._step_compiled(action, measure)
        self.apply(action)
        reward, failed = self.advance()
        return (self.measure() if measure else None), reward, failed

    def _step_compiled(self, action: ArrayLike, measure: bool
                       ) -> tuple[FloatArray | None, FloatArray, NDArray[np.bool_]]:
        """:meth:`step` in one kernel call; the state arrays are replaced by new ones."""
        compiled, a = self._compiled, self._actions(action)
        d = self.d
        if self.disturbances is not None:
            if compiled.streamed:
                d = np.empty(self.d.shape)  # the kernel reads the stream
            elif all_finite(a):  # (else the kernel refuses the action: keep the source)
                d = self.disturbances.step()
        stepped = compiled.step(a, self.x, d, measure)
        self.d = d
        stepped.check()
        self.x, self.u, self.clipped = stepped.x, stepped.u, stepped.clipped
        if self.actuators is not None:
            self._commanded = stepped.commanded
        return stepped.y, stepped.reward, stepped.failed

    def measure_boats(self, idx: NDArray[np.intp]) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Measurements and valid channels of boats ``idx`` alone (the other boats' sensors do
        not advance; for restarting some boats between steps). Compiled, those boats' own
        sensors take the sample, as a single environment's would; in numpy, a copy of the
        chain measures every boat (statistically the same: the restarted boats' own chain
        then takes its first sample one step late)."""
        idx = np.asarray(idx, dtype=np.intp)
        if self._compiled is not None:
            return self._compiled.measure(self.x[idx], idx)
        sensors, self.sensors = self.sensors, copy.deepcopy(self.sensors)
        try:
            y, valid = self.measure(), self.sensors.valid
        finally:
            self.sensors = sensors
        return y[idx], np.broadcast_to(valid, y.shape)[idx]

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Which channels carried a fresh sample at the last measurement (False = held)."""
        compiled = self._compiled
        return compiled.chain.valid if compiled is not None else self.sensors.valid

    def __getstate__(self) -> dict:
        # the compiled path holds compiled objects: rebuilt on unpickling (and in deep copies)
        # from the arrays it shares with the simulator, and the valid channels it keeps
        state = self.__dict__.copy()
        state.pop("_step_rows", None)
        compiled = state.pop("_compiled", None)
        state["_compiled_valid"] = None if compiled is None else compiled.chain.valid
        return state

    def __setstate__(self, state: dict) -> None:
        state = dict(state)
        valid = state.pop("_compiled_valid", None)
        self.__dict__.update(state)
        self._compiled = None
        if hasattr(self, "batch_size"):  # bound
            self._step_rows = RowsStep.of(self.model, self.integrate, self.dt)
        if valid is not None:
            self._compiled = self._compile()
            self._compiled.chain.valid = valid

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator],
              x0: ArrayLike | None = None) -> None:
        """New episodes for boats ``idx``: initial state, disturbances, sensor state."""
        # fresh arrays, never written in place: info dicts may hold views of the old ones
        self.x, self.u, self.d = self.x.copy(), self.u.copy(), self.d.copy()
        batch = getattr(self.initial_state, "batch", None)
        if x0 is not None:
            self.x[idx] = x0
        elif batch is not None and len(idx) > 1:  # (one boat: a call costs less)
            self.x[idx] = batch(rngs)
        else:
            for i, rng in zip(idx, rngs, strict=True):
                self.x[i] = self.initial_state(rng)
        self.u[idx], self.d[idx], self.steps[idx] = self.model.u0, 0, 0
        if self.actuators is not None:
            self._commanded = self._commanded.copy()
            self._commanded[idx] = self.model.u0
        if self.clipped[idx].any():
            self.clipped = self.clipped.copy()
            self.clipped[idx] = False
        if self.disturbances is not None:
            frozen = self.disturbance_seed is not None
            self.disturbances.reset(idx, [np.random.default_rng(self.disturbance_seed)
                                          for _ in idx] if frozen else rngs)
        self.sensors.reset(idx, rngs)
        if self.actuators is not None:
            self.actuators.reset(idx)

    def apply(self, action: ArrayLike) -> None:
        """Map normalised actions (batch x actuators) in [-1, 1] to physical inputs: the
        commanded ones (:attr:`u_commanded`), then through the input effects, if any, the
        applied ones (:attr:`u`).

        Larger actions are clipped and noted in :attr:`clipped`.
        :raises ValueError: NaN or inf in the action, or a wrong shape.
        """
        a = self._actions(action)
        # numpy reductions have microseconds of overhead: small actions are checked in Python
        # (a sum, not a max: max() skips a NaN that is not first)
        total = sum(abs(v) for v in a.ravel().tolist()) if a.size <= 64 else np.abs(a).sum()
        if not math.isfinite(total):
            raise ValueError(f"action contains NaN or inf: {a.tolist()!r}")
        self.u, self.clipped = self.actuation.act(a)
        if self.actuators is not None:
            self._commanded = self.u
            self.u = self.actuators.step(self.u)

    def _actions(self, action: ArrayLike) -> FloatArray:
        """``action`` as a float array (batch x actuators). :raises ValueError: a wrong shape."""
        a = action if isinstance(action, np.ndarray) else np.asarray(action)
        if a.size != self.batch_size * self.n_actions or a.dtype.kind not in "fiub":
            raise ValueError(f"action has shape {a.shape} and dtype {a.dtype}; expected "
                             f"{self.n_actions} number(s) per environment for "
                             f"{self.batch_size} environment(s)")
        # one conversion up front (a fresh C array: the one layout the kernel is compiled for)
        return a.astype(np.float64, order="C").reshape(self.batch_size, self.n_actions)

    def nominal_action(self) -> FloatArray:
        """The normalised action that applies the model's nominal input ``u0`` (for thrusters:
        the least-squares allocation of it)."""
        return self.actuation.nominal_action(self.model)

    def advance(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        """One control period for every boat: returns ``(reward, failed)``.

        :raises FloatingPointError: a boat's state became NaN or inf (naming it).
        """
        if self.disturbances is not None:
            self.d = self.disturbances.step()
        x, u, d = (np.ascontiguousarray(v, dtype=float) for v in (self.x, self.u, self.d))
        reward = np.empty(len(x))
        cost_rows(self._weights, self._reference, x, u, d, reward)
        if self._step_rows is None:  # a model of numpy equations
            self.x = self.integrate(np.concatenate([x, u, d], axis=1))
        else:
            self.x = self._step_rows(x, u, d)
        self.steps = self.steps + self._one
        failed = np.empty(len(x), dtype=bool)
        limit_rows(self.x, self._limited_list, self._low[0], self._high[0], failed)
        return reward, failed

    def measure(self) -> FloatArray:
        """Sensor outputs (batch x channels) of the current states."""
        if self._compiled is not None:
            return self._compiled.measure(self.x)[0]
        outputs = self.x if self._outputs_are_states else self.model.output(self.x)
        true = outputs[:, self.measured]
        if self.effects:
            true = true + self.bias
        # the sensor chain overwrites its input: never hand it a view of the state
        return self.sensors.measure(true.copy() if true.base is outputs else true)
