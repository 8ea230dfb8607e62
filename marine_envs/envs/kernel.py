"""The per-boat step kernel: a control period of every boat in one compiled call.

apply (clip, scale, allocate, actuator effects) -> cost -> integrate (the model's equations and
its effects' terms) -> limits -> sensors (sensor biases, then the chain), boat by boat, the same
code for one boat and for a batch. Each stage is written once (:mod:`~marine_envs.envs.stages`,
the effect terms, the sensor chain) and merged into the kernel's loop; :meth:`Simulator.apply`,
:meth:`~Simulator.advance` and :meth:`~Simulator.measure` run the same stages over the batch's
rows, for what the kernel does not know (user models without compiled equations, sensor chains
of other stages, a simulator with steps of its own). The simulator hands the kernel what it
needs as a :class:`StepPlan` (the kernel knows no simulator). Python keeps the per-boat random
streams (waves, current, wind, noise), which it refills a block at a time, and the info dict.

What does not change from step to step (constants, the sensors' state arrays, the random streams'
rows and cursors) is held in one :class:`KernelState`, so a step passes a handful of arrays: numba
spends tens of nanoseconds on every argument of a call, which for a single environment would
otherwise cost more than the physics.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
from numba.core import types
from numba.experimental import structref

from ..blocks import BLOCK
from ..compiled import compile_for, jit
from ..models import VehicleModel
from ..models.effect_terms import actuate
from ..models.effects import BatchActuators, equations_of
from ..models.integrate import ExactStep, RK4Step, exact_step
from ..sea.processes import DisturbanceSource
from ..sensors import CompiledChain, SensorSuite, measure_chain
from .stages import act, cost, exceeds

#: The fields of a :class:`KernelState`: the dynamics, the actuator effects
#: (:func:`~marine_envs.models.effects.input_table`, then :class:`BatchActuators`' state),
#: then the sensor chain's configuration and its state (:meth:`CompiledChain.configuration`,
#: :meth:`CompiledChain.begin`).
DYNAMICS = ("p", "h", "substeps", "mid", "scale", "allocation", "allocated", "weights",
            "reference", "limited", "low", "high", "output_map", "output_bias", "steps", "boats",
            "streamed", "d_rows", "d_cursor")
ACTUATORS = ("acting", "act_kinds", "act_inputs", "act_u0", "act_values", "act_lengths",
             "act_line", "act_count", "act_previous")
CHAIN = ("bias", "wrap", "mu", "group", "zoom_settings", "limit", "period", "lag", "prob",
         "noisy", "zooming", "holding", "delaying", "dropping",
         "noise_rows", "noise_cursor", "zoom_mu", "count", "held", "buf", "head", "delay_fresh",
         "dropout_rows", "dropout_cursor", "kept", "dropout_fresh")
#: What the kernel returns: every boat stepped; stepped, and a random stream needs its next
#: block (:meth:`~marine_envs.blocks.BlockStream.refill_exhausted`); an action was NaN or inf
#: (nothing changed). Else the first boat whose state diverged.
STEPPED, REFILL, BAD_ACTION = -1, -2, -3


@structref.register
class KernelStateType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class KernelState(structref.StructRefProxy):
    """What a simulator's kernel reads every step and what it keeps from step to step (the
    arrays are shared with the simulator and its sensor stages, not copied)."""

    def __new__(cls, *fields: Any) -> KernelState:
        return structref.StructRefProxy.__new__(cls, *fields)


structref.define_proxy(KernelState, KernelStateType, DYNAMICS + ACTUATORS + CHAIN)


@jit(inline="never")
def new_state(*fields):
    """A :class:`KernelState` of ``fields`` (in the order of :data:`DYNAMICS`, :data:`ACTUATORS`
    and :data:`CHAIN`),
    made by compiled code that is cached (numba compiles the proxy's own constructor anew in
    every process)."""
    return KernelState(*fields)


def step_kernel(integrate: Callable[..., None]) -> Callable[..., int]:
    """The kernel ``step(state, actions, x, d, x_out, u_out, u_cmd, reward, failed, clipped,
    measure, y, valid) -> int`` of a model stepped by ``integrate(x, u, d, p, h, substeps, out,
    work)`` (:func:`~marine_envs.models.integrate.exact_step`, or
    :func:`marine_envs.compiled.rk4` of its equations).

    Writes the disturbances (when they come from one block stream, ``state.streamed``; else
    ``d`` holds them), the next states, the applied and the commanded inputs (the same array
    may be passed for both when there are no actuator effects), the rewards, the limit violations,
    which boats' actions were clipped and, if ``measure``, the measurements and their valid
    channels. Returns a code of :data:`STEPPED` ..., or the first boat whose state became NaN
    or inf (then the sensors and the step counts are as they were).
    """

    @jit
    def step(st, actions, x, d, x_out, u_out, u_cmd, reward, failed, clipped, measure, y, valid):
        n_boats, n_x = x.shape
        if not all_finite(actions):
            return BAD_ACTION
        refill = False
        if st.streamed:  # each boat's current row of its stream
            for b in range(n_boats):
                for j in range(d.shape[1]):
                    d[b, j] = st.d_rows[st.d_cursor[b], j]
            refill = _advance(st.d_cursor)
        # the fields as locals: loads through the state are not hoisted out of the loops
        p, h, substeps, mid, scale = st.p, st.h, st.substeps, st.mid, st.scale
        allocation, allocated, weights, reference = st.allocation, st.allocated, st.weights, \
            st.reference
        acting, kinds, inputs, u0, values, lengths = st.acting, st.act_kinds, st.act_inputs, \
            st.act_u0, st.act_values, st.act_lengths
        line, count, previous = st.act_line, st.act_count, st.act_previous
        n_a, n_u = actions.shape[1], u_out.shape[1]
        f = np.empty(n_a)
        work = np.empty((3, n_x + n_u + d.shape[1]))  # scratch rows of at least [x u d]
        for b in range(n_boats):
            # the actions in [-1, 1] command the actuators over their ranges
            clipped[b] = act(actions[b], mid, scale, allocation, allocated, f, u_cmd[b])
            if acting:  # the commanded inputs through the actuator effects
                for i in range(n_u):
                    u_out[b, i] = u_cmd[b, i]
                actuate(kinds, inputs, u0, values, lengths, line, count, previous, b, u_out[b])
            reward[b] = cost(weights, reference, x[b], u_out[b], d[b])
            integrate(x[b], u_out[b], d[b], p, h, substeps, x_out[b], work)
            for i in range(n_x):
                if not np.isfinite(x_out[b, i]):
                    return b
        limited, low, high, steps = st.limited, st.low, st.high, st.steps
        for b in range(n_boats):
            failed[b] = exceeds(x_out[b], limited, low, high)
            steps[b] += 1
        if measure:
            refill = measure_boats(st, st.boats, x_out, y, valid) or refill
        return REFILL if refill else STEPPED

    return step


@jit(inline="never")  # once per step: compiled once, not into every caller
def _advance(cursor):
    """Move every boat's cursor of a block stream a row on; True when a boat used up its
    block."""
    exhausted = False
    for b in range(cursor.size):
        cursor[b] += 1
        exhausted = exhausted or cursor[b] - b * BLOCK == BLOCK
    return exhausted


@jit(inline="never")  # once per step: compiled once, not into every caller
def measure_boats(st, boats, x, y, valid):
    """The sensors' measurements ``y`` and valid channels of boats ``boats`` (row r of states
    ``x``, ``y`` and ``valid`` is boat ``boats[r]``'s); only their sensors advance. True when a
    sensor's random stream used up a boat's block."""
    m, outputs, bias = y.shape[1], st.output_map, st.output_bias
    z = np.empty((boats.size, m))
    for r in range(boats.size):
        for c in range(m):
            total = 0.0
            for k in range(x.shape[1]):
                total += outputs[c, k] * x[r, k]
            z[r, c] = total + bias[c]  # a sensor-bias effect (0 when none: total is never -0)
    measure_chain(boats, z, st.bias, st.wrap, st.mu, st.group, st.zoom_settings, st.limit,
                  st.period, st.lag, st.prob, st.noisy, st.zooming, st.holding, st.delaying,
                  st.dropping, st.noise_rows, st.noise_cursor, st.zoom_mu, st.count, st.held,
                  st.buf, st.head, st.delay_fresh, st.dropout_rows, st.dropout_cursor, st.kept,
                  st.dropout_fresh, y, valid)
    return _used_up(st.noise_cursor) or _used_up(st.dropout_cursor)


@jit
def _used_up(cursor):
    """True when a boat's cursor reached the end of its block."""
    for b in range(cursor.size):
        if cursor[b] - b * BLOCK == BLOCK:
            return True
    return False

@jit(inline="never")  # once per step: compiled once, not into every caller
def all_finite(a):
    """True when no entry of the 2-D array ``a`` is NaN or inf."""
    for b in range(a.shape[0]):
        for j in range(a.shape[1]):
            if not np.isfinite(a[b, j]):
                return False
    return True


def output_map(model: VehicleModel, measured: list[int]) -> np.ndarray | None:
    """The matrix ``(channels, states)`` giving the measured outputs of a state, or None when
    the model's outputs are not linear in its states."""
    n_x = len(model.state_names)
    C = model.output(np.eye(n_x))[:, measured].T.copy()
    probe = np.random.default_rng(0).normal(size=(3, n_x))
    linear = np.allclose(model.output(probe)[:, measured], probe @ C.T, rtol=1e-14, atol=0)
    return np.ascontiguousarray(C) if linear else None


#: The kernel of each model's equations (made once per process; compiled once per machine).
_KERNELS: dict[Any, Callable[..., int]] = {}


def kernel_for(model: VehicleModel, exact: bool) -> Callable[..., int] | None:
    """The step kernel of ``model`` (exact step or RK4), or None when it has no compiled
    equations."""
    if exact:
        key: Any = exact_step
    elif equations_of(model):
        key = model.equations.core
    else:
        return None
    if key not in _KERNELS:
        _KERNELS[key] = step_kernel(exact_step if exact else model.equations.rk4)
    return _KERNELS[key]


@dataclasses.dataclass(frozen=True, eq=False)
class StepPlan:
    """What a simulator's step is, as the kernel reads it (arrays shared, not copied).

    :param model: the vehicle model (with its effects' terms, if any).
    :param integrate: its step over a control period (exact or RK4).
    :param dt: the control period, s.
    :param sensors: the sensor chain (bound).
    :param batch_size: boats.
    :param mid, scale: each actuator's range as ``mid + scale * action``, actuator units.
    :param allocation: ``(n_actuators, n_inputs)`` map to the model's inputs, or None.
    :param weights, reference: the cost ``-sum(weights * ([x u d] - reference)**2)``
        (reference None: zero).
    :param limited, low, high: the states watched and their limits (the episode ends outside).
    :param steps: each boat's step count (advanced in place).
    :param disturbances: the disturbance source, or None.
    :param actuators: the actuator effects (bound), or None.
    :param output_bias: each measured channel's sensor-bias effect, channel units.
    """

    model: VehicleModel
    integrate: ExactStep | RK4Step
    dt: float
    sensors: SensorSuite
    batch_size: int
    mid: np.ndarray
    scale: np.ndarray
    allocation: np.ndarray | None
    weights: np.ndarray
    reference: np.ndarray | None
    limited: np.ndarray
    low: np.ndarray
    high: np.ndarray
    steps: np.ndarray
    disturbances: DisturbanceSource | None
    actuators: BatchActuators | None
    output_bias: np.ndarray


@dataclasses.dataclass
class Stepped:
    """What a kernel step wrote: next states, applied and commanded inputs, rewards, limit
    violations, clipped actions, measurements and their valid channels (None unless measured),
    and the first boat whose state diverged (-1: none)."""

    x: np.ndarray
    u: np.ndarray
    commanded: np.ndarray
    reward: np.ndarray
    failed: np.ndarray
    clipped: np.ndarray
    y: np.ndarray | None
    diverged: int

    def check(self) -> None:
        """:raises FloatingPointError: a boat's state became NaN or inf (naming it)."""
        if self.diverged >= 0:
            b = self.diverged
            raise FloatingPointError(f"simulation diverged: non-finite state {self.x[b]} of "
                                     f"boat {b} (a parameter or time step out of range?)")


class CompiledStep:
    """A bound simulator's compiled path: its kernel, its compiled sensor chain and what the
    kernel keeps. :meth:`of` returns None for a step the kernel cannot run.

    :param plan: the step (:class:`StepPlan`).
    :param kernel: its step kernel (:func:`kernel_for`).
    :param outputs: the measured outputs' map (:func:`output_map`).
    """

    def __init__(self, plan: StepPlan, kernel: Callable[..., int], outputs: np.ndarray) -> None:
        self.kernel, self.outputs, self.acting = kernel, outputs, plan.actuators is not None
        self.n_inputs = len(plan.model.input_names)
        self.chain = CompiledChain(plan.sensors)
        self.chain.bind(plan.batch_size)
        #: the disturbances' block stream, read by the kernel (None: the simulator steps them)
        self.stream = getattr(plan.disturbances, "stream", None)
        self.measured_shape = (plan.batch_size, len(plan.sensors.channels))
        self.state = self._state(plan)
        self._compile()

    @property
    def streamed(self) -> bool:
        """True when the kernel reads the disturbances from their block stream."""
        return self.stream is not None

    def _compile(self) -> None:
        """Compile the kernel for the arrays :meth:`step` and :meth:`measure` pass it (now, while
        the environment is made and a first use says so: :func:`~marine_envs.compiled.first_use`;
        not at its first step)."""
        rows, flags, grid = np.empty((1, 1)), np.empty(1, dtype=bool), np.empty((1, 1), dtype=bool)
        compile_for(self.kernel, self.state, rows, rows, rows, rows, rows, rows, np.empty(1),
                    flags, flags, True, rows, grid)
        compile_for(measure_boats, self.state, self.chain.boats, rows, rows, grid)

    @classmethod
    def of(cls, plan: StepPlan) -> CompiledStep | None:
        """The compiled path of a step: None when the model has no compiled equations (and is
        not stepped exactly) or parameters per boat, the sensors have stages of other kinds or
        the outputs are not linear in the state."""
        if CompiledChain.of(plan.sensors) is None:
            return None
        exact = isinstance(plan.integrate, ExactStep)
        if not exact and np.ndim(plan.model.constants) != 1:
            return None
        measured = [plan.model.output_names.index(c) for c in plan.sensors.channels]
        outputs = output_map(plan.model, measured)
        kernel = kernel_for(plan.model, exact)
        return None if outputs is None or kernel is None else cls(plan, kernel, outputs)

    def _state(self, plan: StepPlan) -> KernelState:
        """What the kernel keeps: constants, step counts, the streams', the actuators' and the
        sensors' arrays."""
        integrate = plan.integrate
        if isinstance(integrate, ExactStep):
            p, h, substeps = integrate.packed, plan.dt, 1
        else:
            p, h, substeps = plan.model.constants, integrate.h, integrate.substeps
        allocation, stream, weights = plan.allocation, self.stream, plan.weights
        return new_state(
            np.ascontiguousarray(p, dtype=float), float(h), int(substeps),
            plan.mid.copy(), plan.scale.copy(),
            np.zeros((1, 1)) if allocation is None else allocation, allocation is not None,
            weights.copy(),
            np.zeros(weights.size) if plan.reference is None else plan.reference,
            plan.limited.astype(np.int64), plan.low.copy(), plan.high.copy(),
            self.outputs, np.ascontiguousarray(plan.output_bias, dtype=float), plan.steps,
            self.chain.boats, stream is not None,
            np.zeros((1, 1)) if stream is None else stream.rows,
            np.zeros(1, dtype=np.int64) if stream is None else stream.cursor,
            *self._actuators(plan.actuators, plan.batch_size),
            *self.chain.configuration(), *self.chain.begin())

    @staticmethod
    def _actuators(actuators: BatchActuators | None, boats: int) -> tuple:
        """The :data:`ACTUATORS` fields: the effects' table and state (empty when none)."""
        if actuators is None:
            integers, floats = np.zeros(0, dtype=np.int64), np.zeros(0)
            return (False, integers, integers, floats, floats, integers,
                    np.zeros((boats, 0, 1)), np.zeros((boats, 0), dtype=np.int64),
                    np.zeros((boats, 0)))
        return (True, *actuators.table, actuators.line, actuators.count, actuators.previous)

    def step(self, actions: np.ndarray, x: np.ndarray, d: np.ndarray, measure: bool) -> Stepped:
        """A control period of every boat from states ``x`` and disturbances ``d`` (written,
        when the kernel reads them from their stream) under ``actions`` (batch x actuators,
        C-contiguous floats): new arrays.

        :raises ValueError: NaN or inf in the actions (nothing changed).
        """
        n = x.shape[0]
        x_next, u = np.empty(x.shape), np.empty((n, self.n_inputs))  # (empty_like: 3x more)
        commanded = np.empty(u.shape) if self.acting else u
        reward, failed, clipped = np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        y = np.empty(self.measured_shape if measure else (0, 0))
        valid = np.empty(y.shape, dtype=bool)
        status = self.kernel(self.state, actions, x, d, x_next, u, commanded, reward, failed,
                             clipped, measure, y, valid)
        if status == BAD_ACTION:
            raise ValueError(f"action contains NaN or inf: {actions.tolist()!r}")
        if status == REFILL:
            self.refill()
        if measure and status < 0:
            self.chain.valid = valid
        return Stepped(x_next, u, commanded, reward, failed, clipped, y if measure else None,
                       max(status, -1))

    def measure(self, x: np.ndarray, boats: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Measurements and valid channels of boats ``boats`` (default: every boat; then they
        are the chain's :attr:`~CompiledChain.valid`) of their states ``x``."""
        every = boats is None
        boats = self.chain.boats if every else np.asarray(boats, dtype=np.int64)
        y = np.empty((boats.size, self.measured_shape[1]))
        valid = np.empty(y.shape, dtype=bool)
        if measure_boats(self.state, boats, np.ascontiguousarray(x, dtype=float), y, valid):
            self.refill()
        if every:
            self.chain.valid = valid
        return y, valid

    def streams(self) -> list:
        """The block streams the kernel reads: sensor noise, dropout, disturbances."""
        streams = [getattr(self.chain.noise, "stream", None),
                   getattr(self.chain.dropout, "stream", None), self.stream]
        return [s for s in streams if s is not None]

    def refill(self) -> None:
        """Refill the random streams whose blocks the kernel used up."""
        for stream in self.streams():
            stream.refill_exhausted()


__all__ = ["BAD_ACTION", "REFILL", "STEPPED", "CompiledStep", "KernelState", "StepPlan",
           "Stepped", "all_finite",
           "kernel_for", "measure_boats", "new_state", "output_map", "step_kernel"]
