"""The public face of a simulated vehicle, ``System``, and the one action map, ``Actuation``.

An environment is a :class:`System` (what is simulated: model, control period, actuators, task,
sensors, disturbances, initial states, effects) plus the batch state of its boats.
``env.unwrapped.system`` (single and vector environments alike) is the contract between the
environment and everything above it: estimators, LQR, agents, benchmarks and the diagnosis
design from it, never from the simulator behind the environment. A :class:`System` is frozen
and holds copies: nothing done to it changes an environment.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import types
from collections.abc import Callable
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models import VehicleModel
from ..models.effects import Effect
from ..models.integrate import ExactStep
from ..sea.processes import DisturbanceSource
from ..sensors import SensorSuite
from .stages import act_rows, command_rows

FloatArray = NDArray[np.float64]
#: Draws one boat's initial state (state units) from its generator.
InitialState = Callable[[np.random.Generator], FloatArray]


@dataclasses.dataclass
class Task:
    """A regulation task: drive the state to ``x_ref`` with little input.

    Stage cost of step k: ``(x_k - x_ref)' diag(q) (x_k - x_ref) + (u_k - u_ref)' diag(r)
    (u_k - u_ref)``, exactly the discrete LQR cost, so an episode's return is minus the LQR cost
    of its trajectory; the reward is ``-reward_scale * cost``. Angles enter the cost as the
    model's (unwrapped) linear states, as they do in LQR. An episode terminates when a state
    leaves ``[low, high]`` (state units; infinite where unconstrained).
    """

    q: FloatArray
    r: FloatArray
    x_ref: FloatArray
    u_ref: FloatArray
    low: FloatArray
    high: FloatArray
    reward_scale: float = 1.0


@dataclasses.dataclass(frozen=True, eq=False)
class Actuation:
    """How actions reach the model: each action in [-1, 1] commands an actuator over
    ``[low, high]`` (its physical range), and ``matrix`` maps actuator outputs to the model's
    inputs (``u = matrix @ f``; None = the actuators are the inputs), e.g. thruster forces to
    generalised forces through an allocation matrix. :meth:`to_input`, :meth:`to_action` and
    :meth:`nominal_action` are the one map between actions and inputs.

    :param names: actuator names, one per action.
    :param low, high: actuator ranges, actuator units.
    :param matrix: ``(n_inputs, n_actuators)`` map, or None.
    """

    names: tuple[str, ...]
    low: FloatArray
    high: FloatArray
    matrix: FloatArray | None = None

    @classmethod
    def direct(cls, model: VehicleModel) -> Actuation:
        """Actions command the model's inputs over :attr:`VehicleModel.u_bounds`."""
        low, high = model.u_bounds
        return cls(model.input_names, np.asarray(low, float), np.asarray(high, float))

    def __post_init__(self) -> None:
        if not (len(self.names) == self.low.size == self.high.size
                and np.all(self.low < self.high)):
            raise ValueError(f"actuator ranges low={self.low.tolist()} high="
                             f"{self.high.tolist()} are invalid for {self.names}: low < high")
        if self.matrix is not None and np.shape(self.matrix)[1:] != (len(self.names),):
            raise ValueError(f"matrix has shape {np.shape(self.matrix)}; expected (n_inputs, "
                             f"{len(self.names)}), a column per actuator of {self.names}")
        low, high = self.low, self.high
        # shaped (1, n): numpy broadcasts equal-rank operands faster (the simulator's step)
        object.__setattr__(self, "u_scale", ((high - low) / 2)[None, :])
        object.__setattr__(self, "u_mid", ((high + low) / 2)[None, :])
        matrix = self.matrix
        object.__setattr__(self, "allocation",
                           None if matrix is None else np.asarray(matrix, float).T.copy())
        object.__setattr__(self, "to_actuators",
                           None if matrix is None else np.linalg.pinv(matrix))

    #: Half and middle of each actuator's range, ``(1, n_actuators)``, actuator units.
    u_scale: FloatArray = dataclasses.field(init=False, repr=False)
    u_mid: FloatArray = dataclasses.field(init=False, repr=False)
    #: ``matrix`` transposed, ``(n_actuators, n_inputs)`` (``u = f @ allocation``), or None.
    allocation: FloatArray | None = dataclasses.field(init=False, repr=False)
    #: The least-squares map of inputs to actuators, ``pinv(matrix)``, or None.
    to_actuators: FloatArray | None = dataclasses.field(init=False, repr=False)

    @property
    def size(self) -> int:
        """Number of actuators (the action's width)."""
        return len(self.names)

    def to_input(self, a: ArrayLike) -> FloatArray:
        """Model inputs (input units) of normalised actions ``a`` in [-1, 1], shape
        ``(n_actuators,)`` or ``(batch, n_actuators)`` (not clipped here)."""
        a = np.asarray(a, dtype=float)
        rows = np.array(a.reshape(-1, self.size), order="C")  # (a fresh writable C array)
        u = np.empty((len(rows), self.n_inputs))
        command_rows(rows, *self._map(), u)
        return u[0] if a.ndim == 1 else u

    def act(self, a: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The model inputs of actions ``a`` (batch x actuators, C-contiguous floats) clipped
        to [-1, 1], and which boats' actions were clipped."""
        u, clipped = np.empty((len(a), self.n_inputs)), np.empty(len(a), dtype=bool)
        act_rows(a, *self._map(), u, clipped)
        return u, clipped

    @property
    def n_inputs(self) -> int:
        """Number of model inputs the actuators drive."""
        return self.size if self.allocation is None else self.allocation.shape[1]

    def _map(self) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
        """The map's arrays as :func:`~marine_envs.envs.stages.command` reads them."""
        allocation = self.allocation
        return (self.u_mid[0], self.u_scale[0],
                np.zeros((1, 1)) if allocation is None else allocation, allocation is not None)

    def to_action(self, u: ArrayLike) -> FloatArray:
        """The normalised actions that apply inputs ``u`` (input units), shape ``(n_inputs,)``
        or ``(batch, n_inputs)``: through the actuators' least-squares allocation of ``u``
        (``pinv(matrix)``) where actuators are allocated; not clipped (beyond [-1, 1] where
        ``u`` is out of range)."""
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            f = u if self.to_actuators is None else self.to_actuators @ u
            return (f - self.u_mid[0]) / self.u_scale[0]
        f = u if self.to_actuators is None else u @ self.to_actuators.T
        return (f - self.u_mid) / self.u_scale

    def nominal_action(self, model: VehicleModel) -> FloatArray:
        """The normalised action that applies the model's nominal input ``u0`` (for thrusters:
        the least-squares allocation of it)."""
        return self.to_action(model.u0)

    def folded(self) -> tuple[FloatArray, FloatArray]:
        """:meth:`to_action` as one affine map ``a = M u + c`` (equal to rounding), for a
        controller that folds it into its gain (:class:`agents.lqr.LQRPolicy`)."""
        return folded_action_map(self.low, self.high, self.to_actuators)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Actuation):
            return NotImplemented
        return same(self, other)

    __hash__ = None  # type: ignore[assignment]  # (equal by value, and mutable arrays)


def folded_action_map(low: ArrayLike, high: ArrayLike, to_actuators: ArrayLike | None = None
                      ) -> tuple[FloatArray, FloatArray]:
    """``(M, c)`` with ``a = M u + c`` the normalised actions of inputs ``u``: actuator ranges
    ``[low, high]`` (actuator units) reached through ``to_actuators`` (inputs to actuators,
    ``(n_actuators, n_inputs)``; None = the actuators are the inputs)."""
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    mid, half = (high + low) / 2, (high - low) / 2
    M = np.eye(low.size) if to_actuators is None else np.asarray(to_actuators, dtype=float)
    return M / half[:, None], -(mid / half)


@dataclasses.dataclass(frozen=True, eq=False)
class System:
    """A simulated vehicle as everything above the environment sees it (read-only).

    Made by an environment (:meth:`of`) from its simulator before any boat is bound, so it
    holds configuration only, copied: changing it changes no environment. Two systems are
    equal when every configuration value is (a single environment's and its vector twin's
    are).

    :ivar vehicle: the environment's vehicle, as in its id (``"USV"``).
    :ivar model: the vehicle model as simulated (with the state terms of ``effects``).
    :ivar dt: control period, s.
    :ivar actuation: the map between actions and the model's inputs.
    :ivar task: cost (the negative reward) and termination limits.
    :ivar sensors: the sensor chain's configuration (``channels``, ``stages``).
    :ivar disturbances: the source of the model's disturbance inputs (one source, or several
        side by side in a :class:`~marine_envs.sea.processes.Stacked`), each describing its own
        linear model (``linear_model(dt)``); None for none.
    :ivar initial_state: draws one boat's initial state from a generator.
    :ivar effects: physics added to the nominal model (``effects=``).
    :ivar integrator: ``"exact"`` (linear models) or ``"rk4"``.
    :ivar substeps: integration steps per control period (1 for the exact step).
    :ivar disturbance_seed: the seed of a frozen sea (every episode the same), or None.
    """

    vehicle: str
    model: VehicleModel
    dt: float
    actuation: Actuation
    task: Task
    sensors: SensorSuite
    disturbances: DisturbanceSource | None
    initial_state: InitialState
    effects: tuple[Effect, ...] = ()
    integrator: Literal["exact", "rk4"] = "exact"
    substeps: int = 1
    disturbance_seed: int | None = None

    @classmethod
    def of(cls, sim: Any, vehicle: str) -> System:
        """The system of an unbound :class:`~marine_envs.envs.core.Simulator` (an
        environment's, before ``bind``): a copy of it, which :meth:`simulator` copies again."""
        template = copy.deepcopy(sim, {id(sim.model): sim.model})  # a model is stateless
        task = template.task
        for array in (task.q, task.r, task.x_ref, task.u_ref, task.low, task.high):
            array.flags.writeable = False
        exact = isinstance(template.integrate, ExactStep)
        system = cls(vehicle, template.model, float(template.dt), template.actuation, task,
                     template.sensors, template.disturbances, template.initial_state,
                     tuple(template.effects), "exact" if exact else "rk4",
                     1 if exact else int(template.integrate.substeps),
                     template.disturbance_seed)
        object.__setattr__(system, "_template", template)
        return system

    def simulator(self, batch_size: int) -> Any:
        """A new :class:`~marine_envs.envs.core.Simulator` of this system for ``batch_size``
        boats, apart from any environment (a designer's calibration runs); boats start after
        ``reset``.

        :raises ValueError: a system not made by :meth:`of` (it has no simulator).
        """
        template = getattr(self, "_template", None)
        if template is None:
            raise ValueError("this System was not made by System.of: it has no simulator")
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        sim = copy.deepcopy(template, {id(self.model): self.model})
        sim.bind(int(batch_size))
        return sim

    @property
    def channels(self) -> tuple[str, ...]:
        """The measured channels, in the observation's order."""
        return tuple(self.sensors.channels)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, System):
            return NotImplemented
        return all(same(getattr(self, f.name), getattr(other, f.name))
                   for f in dataclasses.fields(self))

    __hash__ = None  # type: ignore[assignment]


_ATOMS = (str, bytes, int, bool, type(None), complex, range, slice)
_BY_IDENTITY = (types.FunctionType, types.BuiltinFunctionType, types.MethodType, type,
                types.ModuleType)


def same(a: Any, b: Any, _seen: set[tuple[int, int]] | None = None) -> bool:
    """True when ``a`` and ``b`` hold equal values throughout: arrays element by element (NaN
    equal to NaN), containers item by item, other objects attribute by attribute; functions,
    classes and compiled functions by identity."""
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, _ATOMS) or isinstance(a, np.generic):
        return bool(a == b) or (a != a and b != b)
    if isinstance(a, np.ndarray):
        nan = a.dtype.kind in "fc"
        return a.shape == b.shape and a.dtype == b.dtype and bool(
            np.array_equal(a, b, equal_nan=nan))
    seen = set() if _seen is None else _seen
    key = (id(a), id(b))
    if key in seen:  # a cycle: equal unless shown otherwise elsewhere
        return True
    seen.add(key)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(same(x, y, seen) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k], seen) for k in a)
    if isinstance(a, np.random.Generator):
        return same(a.bit_generator.state, b.bit_generator.state, seen)
    if hasattr(a, "__func__") and hasattr(a, "__self__"):  # bound methods
        return a.__func__ is b.__func__ and same(a.__self__, b.__self__, seen)
    if isinstance(a, functools.partial):
        return same((a.func, a.args, a.keywords), (b.func, b.args, b.keywords), seen)
    if isinstance(a, _BY_IDENTITY) or type(a).__module__.startswith("numba"):
        return False  # (not the same object)
    state_a = getattr(a, "__dict__", None)
    return a == b if state_a is None else same(state_a, b.__dict__, seen)


__all__ = ["Actuation", "InitialState", "System", "Task", "folded_action_map", "same"]
