"""The vehicle-model protocol shared by every vehicle (docs/architecture.md, contract 1).

A model is pure physics: continuous-time dynamics ``x_dot = rhs(x, u, d)`` in SI units and
radians, vectorised over any leading batch axes, and its linearisation. It knows nothing about
Gymnasium, randomness or sensors. Parameters live in a frozen dataclass so that variants are made
with :func:`dataclasses.replace` (or :meth:`VehicleModel.with_params`) and validated on creation.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..compiled import Equations

FloatArray = NDArray[np.float64]


def require(condition: bool, name: str, value: Any, expectation: str) -> None:
    """Raise ``ValueError`` naming the offending parameter unless ``condition`` holds."""
    if not condition:
        raise ValueError(f"{name}={value!r} is invalid: {expectation}")


class CompiledParameters(NamedTuple):
    """How estimated parameters enter a model's compiled equations (what
    :meth:`VehicleModel.compiled_parameters` declares; every function compiled).

    :param prepare: ``prepare(theta, table, q)``: writes the packed constants of the parameter
        values ``theta`` ``(p,)`` into ``q`` (which holds those of the table's values).
    :param jacobian: ``jacobian(x, u, d, q, table, A)``: writes ``d f / d theta`` into the last
        ``p`` columns of ``A`` ``(n, n + p)``, at constants ``q``.
    :param constants: ``q`` at the table's parameter values.
    :param table: what ``prepare`` and ``jacobian`` read: floats and integers.
    """

    prepare: Callable[..., None]
    jacobian: Callable[..., None]
    constants: FloatArray
    table: tuple[FloatArray, NDArray[np.int64]]


class VehicleModel(ABC):
    """Base class of all vehicle models.

    Subclasses set the class attributes below and give their equations once, compiled, as
    :attr:`equations` with the constants they read (:meth:`pack`); :meth:`rhs` runs them on every
    row of a batch, and the environments' step kernel integrates them (a model may instead
    implement :meth:`rhs` itself in numpy: it is then stepped by the numpy path). ``linearize``
    defaults to central finite differences of ``rhs``; linear models override it with the exact
    matrices.
    """

    #: One boat's equations ``core(x, u, d, p, out)``, compiled (:mod:`marine_envs.compiled`),
    #: with ``p`` = :attr:`constants`; None for a model whose :meth:`rhs` is its own.
    equations: ClassVar[Equations | None] = None

    name: ClassVar[str]
    state_names: ClassVar[tuple[str, ...]]
    input_names: ClassVar[tuple[str, ...]]
    disturbance_names: ClassVar[tuple[str, ...]]
    #: SI unit of each state, input and disturbance, in the order of the names.
    state_units: ClassVar[tuple[str, ...]]
    input_units: ClassVar[tuple[str, ...]]
    disturbance_units: ClassVar[tuple[str, ...]]
    #: True when ``rhs`` is affine in (x, u, d): the environment then steps it exactly (ZOH).
    is_linear: ClassVar[bool] = False
    #: Parameters in which ``rhs`` is affine (a coefficient times a term of the forces, with the
    #: mass matrix not involved): :meth:`rhs_with` varies them per row for one ``rhs`` call each.
    affine_parameters: ClassVar[frozenset[str]] = frozenset()
    #: True when :meth:`rhs` reads its parameters at call time with numpy arithmetic only, so a
    #: parameter may hold one value per batch row (:meth:`with_rows`): one ``rhs`` call for any
    #: number of parameter sets.
    row_parameters: ClassVar[bool] = False
    #: States of the model's own disturbance model (a DP observer's bias and wave-frequency
    #: motion), driven by unit-intensity white disturbances: the model states their statistics,
    #: so a diagnosis takes their process noise from the model and looks for no term in them.
    noise_model_states: ClassVar[tuple[str, ...]] = ()
    #: The disturbance channels one wave elevation drives, each through the model's own wave
    #: coupling (:mod:`marine_envs.sea.coupling`, a response per metre of wave amplitude): in a
    #: seaway they are one process, not independent ones, and a diagnosis models them so.
    wave_disturbances: ClassVar[tuple[str, ...]] = ()
    #: The gain and time constant ``(K, T)`` of a first-order lag ``T x' + x = K u`` in the
    #: model: fits move them as ``K/T`` and ``1/T``, which stay finite where the lag turns
    #: unstable (``1/T`` through 0, ``T`` through infinity).
    lag_parameters: ClassVar[tuple[str, str] | None] = None
    #: Parameters known only roughly (fitted, estimated), which a diagnosis may calibrate by
    #: itself when free simulation cannot follow the records; empty: any parameter may be.
    calibration_candidates: ClassVar[tuple[str, ...]] = ()
    #: Richer host models of the same records (e.g. ``nomoto``'s ``("mmg",)``), which a
    #: diagnosis validates across amplitude classes when this model's corrections do not hold.
    richer_models: ClassVar[tuple[str, ...]] = ()

    @property
    def actuator_names(self) -> tuple[str, ...]:
        """The inputs a controller commands: every input, unless the model takes measured
        disturbances as inputs too (:class:`MeasuredDisturbances`)."""
        return self.input_names

    @property
    def environment_disturbances(self) -> tuple[str, ...]:
        """The disturbance channels that are the environment (sea, wind, current), not a
        command nor the white noise of the model's own disturbance model: what a filter that
        does not measure them may estimate as coloured states. Default: every channel, none
        for a model with :attr:`noise_model_states`."""
        return () if self.noise_model_states else self.disturbance_names

    def __init__(self, params: Any) -> None:
        self.params = params

    # -- nominal operating point -------------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Nominal (equilibrium) state."""
        return np.zeros(len(self.state_names))

    @property
    def u0(self) -> FloatArray:
        """Nominal input that holds :attr:`x0` in equilibrium with zero disturbance."""
        return np.zeros(len(self.input_names))

    # -- outputs: what a sensor can measure ---------------------------------------------------
    @property
    def output_names(self) -> tuple[str, ...]:
        """Quantities a sensor can measure: the states, plus any derived outputs a model adds
        (e.g. the DP vessel's position = low-frequency + wave-frequency motion)."""
        return self.state_names

    @property
    def output_units(self) -> tuple[str, ...]:
        """SI unit of each output, in the order of :attr:`output_names`."""
        return self.state_units

    def output(self, x: FloatArray) -> FloatArray:
        """All outputs of states ``x`` (shape ``(..., n_x)``), shape ``(..., n_outputs)``."""
        return x

    @property
    @abstractmethod
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Physical input limits ``(low, high)`` in the units of :attr:`input_units`."""

    # -- dynamics ------------------------------------------------------------------------------
    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """Continuous-time state derivative: :attr:`equations` on every row.

        :param x: state, shape ``(..., n_x)``, units :attr:`state_units`.
        :param u: input, shape ``(..., n_u)``, units :attr:`input_units`.
        :param d: disturbance, shape ``(..., n_d)``, units :attr:`disturbance_units`; ``None``
            means zero.
        :return: ``x_dot``, shape ``(..., n_x)``.
        """
        if self.equations is None:
            raise NotImplementedError(f"{type(self).__name__} gives neither equations nor rhs")
        x, u, d = self._split(x, u, d)
        return self.equations(x, u, d, self.constants)

    @functools.cached_property
    def constants(self) -> FloatArray:
        """The constants :attr:`equations` read, packed (:meth:`pack`): shape ``(p,)``, or
        ``(..., p)`` when parameters hold one value per batch row (:meth:`with_rows`)."""
        return np.asarray(self.pack(), dtype=float)

    def pack(self) -> FloatArray:
        """The constants of :attr:`equations` from :attr:`params`, in the order the equations
        read them (numpy arithmetic, so that parameters given per row pack per row)."""
        raise NotImplementedError(f"{type(self).__name__} has no compiled equations")

    def linearize(
        self, x0: ArrayLike | None = None, u0: ArrayLike | None = None, eps: float = 1e-6,
        d0: ArrayLike | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Jacobians ``(A, B, E)`` of :meth:`rhs` at ``(x0, u0, d0)`` (default ``d0 = 0``) by
        central differences."""
        x0 = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        u0 = self.u0 if u0 is None else np.asarray(u0, dtype=float)
        d0 = np.zeros(len(self.disturbance_names)) if d0 is None else \
            np.asarray(d0, dtype=float)
        return tuple(  # type: ignore[return-value]
            _jacobian(lambda z, i=i: self.rhs(*_replace_arg((x0, u0, d0), i, z)), arg, eps)
            for i, arg in enumerate((x0, u0, d0))
        )

    def rhs_with(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                 params: Mapping[str, ArrayLike]) -> FloatArray:
        """:meth:`rhs` with the named parameters replaced, row by row (what an estimator of the
        parameters needs: one filter per row, each with its own values).

        :param params: ``{name: value}``; each value a scalar or an array of the batch shape of
            ``x``, in the parameter's units. Names as in :attr:`params`.
        :return: ``x_dot``, shape ``(..., n_x)``.

        Exact for every parameter. Parameters in :attr:`affine_parameters` cost one ``rhs`` call
        each; any other makes one model per distinct value (slow: meant for small batches).
        """
        if not params:
            return self.rhs(x, u, d)
        self.check_parameter_names(params)
        x, u, d = self._split(x, u, d)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1],
                                    *(np.shape(v) for v in params.values()))
        flat = [np.broadcast_to(a, (*shape, a.shape[-1])).reshape(-1, a.shape[-1])
                for a in (x, u, d)]
        values = {k: np.broadcast_to(np.asarray(v, dtype=float), shape).ravel()
                  for k, v in params.items()}
        other = [k for k in values if k not in self.affine_parameters]
        if self.row_parameters:
            return self.with_rows(**values).rhs(*flat).reshape(*shape, -1)
        if not other:
            return self._rhs_affine(*flat, values).reshape(*shape, -1)
        out = np.empty((flat[0].shape[0], len(self.state_names)))
        keys = np.column_stack([values[k] for k in other])
        distinct, group = np.unique(keys, axis=0, return_inverse=True)
        for i, row in enumerate(distinct):
            rows = group.ravel() == i
            model = self.with_params(**dict(zip(other, row.tolist(), strict=True)))
            rest = {k: v[rows] for k, v in values.items() if k not in other}
            out[rows] = model._rhs_affine(*(a[rows] for a in flat), rest)
        return out.reshape(*shape, -1)

    def parameter_jacobian(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                           params: Mapping[str, ArrayLike]) -> FloatArray | None:
        """``d rhs_with / d params`` at the given values, shape ``(..., n_x, p)`` in the order of
        ``params``, exact; or None when the model has no exact form (estimators then take
        differences of :meth:`rhs_with`). Here: exact when every name is in
        :attr:`affine_parameters` (one ``rhs`` call each)."""
        self.check_parameter_names(params)
        if not params or not set(params) <= self.affine_parameters:
            return None
        x, u, d = self._split(x, u, d)
        nominal = self.rhs(x, u, d)
        columns = []
        for name in params:
            step = max(1.0, abs(float(getattr(self.params, name))))
            columns.append((self._unit_step(name, step).rhs(x, u, d) - nominal) / step)
        return np.stack(columns, axis=-1)

    def compiled_parameters(self, names: tuple[str, ...]) -> CompiledParameters | None:
        """How the parameters ``names`` (as :meth:`rhs_with` means them) enter the model's
        compiled equations, for an estimator that appends them to its state and runs compiled;
        None (here) when the model declares no such form (the estimator then runs in numpy)."""
        return None

    def check_parameter_names(self, names: Iterable[str]) -> tuple[str, ...]:
        """``names`` as a tuple, each a field of :attr:`params`.

        :raises ValueError: an unknown name, listing the known ones.
        """
        names = tuple(names)
        known = [f.name for f in dataclasses.fields(self.params)]
        unknown = sorted(set(names) - set(known))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown} for model {self.name!r}; "
                             f"known: {', '.join(known)}")
        return names

    def _rhs_affine(self, x: FloatArray, u: FloatArray, d: FloatArray,
                    values: Mapping[str, FloatArray]) -> FloatArray:
        """``rhs`` plus the exact change of each affine parameter from its nominal value."""
        nominal_rhs = self.rhs(x, u, d)
        out = nominal_rhs.copy()
        for name, value in values.items():
            nominal = float(getattr(self.params, name))
            step = max(1.0, abs(nominal))  # affine: any step is exact; this one is well scaled
            change = self._unit_step(name, step).rhs(x, u, d) - nominal_rhs
            out += change * ((value - nominal) / step)[:, None]
        return out

    def _unit_step(self, name: str, step: float) -> VehicleModel:
        cache = self.__dict__.setdefault("_step_models", {})
        if name not in cache:
            cache[name] = self.with_params(**{name: float(getattr(self.params, name)) + step})
        return cache[name]

    # -- variants ------------------------------------------------------------------------------
    def with_params(self, **changes: float) -> VehicleModel:
        """A copy of this model with some parameters replaced (validated; names as in
        docs/models.md)."""
        self.check_parameter_names(changes)
        return type(self)(dataclasses.replace(self.params, **changes))

    def with_rows(self, **values: ArrayLike) -> VehicleModel:
        """A copy whose named parameters hold one value per batch row (arrays broadcasting
        against the batch shape of ``x``; not validated: for estimators that try many values at
        once). :raises TypeError: the model does not declare :attr:`row_parameters`."""
        if not self.row_parameters:
            raise TypeError(f"model {self.name!r} cannot take a parameter per row")
        self.check_parameter_names(values)
        params = copy.copy(self.params)
        for name, value in values.items():  # frozen: bypass __setattr__, not the names check
            object.__setattr__(params, name, np.asarray(value, dtype=float))
        model = copy.copy(self)
        model.params = params
        model.__dict__.pop("_step_models", None)
        model.__dict__.pop("constants", None)
        return model

    def _split(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None):
        """Arrays of states, inputs and disturbances broadcast to one batch shape."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        d = np.zeros(len(self.disturbance_names)) if d is None else np.asarray(d, dtype=float)
        for arr, names, what in ((x, self.state_names, "x"), (u, self.input_names, "u"),
                                 (d, self.disturbance_names, "d")):
            if arr.shape[-1:] != (len(names),):
                raise ValueError(f"{what} must have last axis {len(names)} ({', '.join(names)}), "
                                 f"got shape {arr.shape}")
        return x, u, d

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params!r})"


class LinearizedModel(VehicleModel):
    """The linearisation of a model about a point, as a model of its own (same names, units,
    bounds and outputs): ``x_dot = f0 + A (x - x0) + B (u - u0) + E d`` with ``f0 = rhs(x0, u0)``.

    Environments step it exactly (zero-order hold); estimators and LQR use it as their design
    model. The difference to the nonlinear model is physics a diagnosis may find.

    :param model: the nonlinear model.
    :param x0, u0: the point (default: the model's nominal point).
    """

    is_linear: ClassVar[bool] = True

    def __init__(self, model: VehicleModel, x0: ArrayLike | None = None,
                 u0: ArrayLike | None = None) -> None:
        super().__init__(model.params)
        self.nonlinear = model
        for attr in ("name", "state_names", "input_names", "disturbance_names", "state_units",
                     "input_units", "disturbance_units"):
            setattr(self, attr, getattr(model, attr))
        self._x0 = model.x0 if x0 is None else np.asarray(x0, dtype=float)
        self._u0 = model.u0 if u0 is None else np.asarray(u0, dtype=float)
        self.A, self.B, self.E = model.linearize(self._x0, self._u0)
        self.f0 = model.rhs(self._x0, self._u0)

    @property
    def x0(self) -> FloatArray:
        return self._x0

    @property
    def u0(self) -> FloatArray:
        return self._u0

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        return self.nonlinear.u_bounds

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.nonlinear.output_names

    @property
    def output_units(self) -> tuple[str, ...]:
        return self.nonlinear.output_units

    def output(self, x: FloatArray) -> FloatArray:
        return self.nonlinear.output(x)

    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        x, u, d = self._split(x, u, d)
        return self.f0 + (x - self._x0) @ self.A.T + (u - self._u0) @ self.B.T + d @ self.E.T

    def linearize(self, x0: ArrayLike | None = None, u0: ArrayLike | None = None,
                  eps: float = 0.0, d0: ArrayLike | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The matrices (the same at every point)."""
        return self.A, self.B, self.E

    def with_params(self, **changes: float) -> LinearizedModel:
        """The linearisation of the nonlinear model with some parameters replaced."""
        return LinearizedModel(self.nonlinear.with_params(**changes))

    def __repr__(self) -> str:
        return f"LinearizedModel({self.nonlinear!r})"


class MeasuredDisturbances(VehicleModel):
    """A model whose named disturbance channels were measured (an anemometer's wind, an ADCP's
    current, a logged morph command): they become inputs after the model's own, so an estimator
    or a diagnosis takes them from the recording instead of estimating them. Same name, states,
    outputs and parameters as the model; the other disturbance channels stay disturbances.

    :param model: the model.
    :param names: its measured disturbance channels (names in ``model.disturbance_names``).
    :raises ValueError: an unknown, repeated or missing name.
    """

    def __init__(self, model: VehicleModel, names: Sequence[str]) -> None:
        names = tuple(names)
        unknown = sorted(set(names) - set(model.disturbance_names))
        if unknown or not names or len(set(names)) < len(names):
            raise ValueError(f"measured disturbances {list(names)} for model {model.name!r}: "
                             f"give distinct names of {', '.join(model.disturbance_names)}")
        super().__init__(model.params)
        self.model, self.measured_disturbances = model, names
        for attr in ("name", "state_names", "state_units", "is_linear", "affine_parameters",
                     "row_parameters", "noise_model_states"):
            setattr(self, attr, getattr(model, attr))
        units = dict(zip(model.disturbance_names, model.disturbance_units, strict=True))
        self._measured = [model.disturbance_names.index(n) for n in names]
        self._rest = [i for i in range(len(units)) if i not in self._measured]
        self.input_names = model.input_names + names
        self.input_units = model.input_units + tuple(units[n] for n in names)
        self.disturbance_names = tuple(model.disturbance_names[i] for i in self._rest)
        self.disturbance_units = tuple(model.disturbance_units[i] for i in self._rest)

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return self.model.actuator_names

    @property
    def environment_disturbances(self) -> tuple[str, ...]:
        return tuple(n for n in self.model.environment_disturbances
                     if n not in self.measured_disturbances)

    @property
    def wave_disturbances(self) -> tuple[str, ...]:  # type: ignore[override]
        return tuple(n for n in self.model.wave_disturbances
                     if n not in self.measured_disturbances)

    @property
    def x0(self) -> FloatArray:
        return self.model.x0

    @property
    def u0(self) -> FloatArray:
        """The model's nominal input, and no disturbance."""
        return np.concatenate([self.model.u0, np.zeros(len(self.measured_disturbances))])

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """The model's input limits; a measured disturbance is unbounded."""
        free = np.full(len(self.measured_disturbances), np.inf)
        low, high = self.model.u_bounds
        return np.concatenate([low, -free]), np.concatenate([high, free])

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.model.output_names

    @property
    def output_units(self) -> tuple[str, ...]:
        return self.model.output_units

    def output(self, x: FloatArray) -> FloatArray:
        return self.model.output(x)

    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """The model's ``rhs`` with ``u = [inputs, measured disturbances]`` and ``d`` the
        others."""
        x, u, d = self._split(x, u, d)
        n = len(self.model.input_names)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1])
        full = np.zeros((*shape, len(self.model.disturbance_names)))
        full[..., self._measured] = u[..., n:]
        full[..., self._rest] = d
        return self.model.rhs(x, u[..., :n], full)

    def with_params(self, **changes: float) -> MeasuredDisturbances:
        return MeasuredDisturbances(self.model.with_params(**changes),
                                    self.measured_disturbances)

    def with_rows(self, **values: ArrayLike) -> MeasuredDisturbances:
        return MeasuredDisturbances(self.model.with_rows(**values), self.measured_disturbances)

    def __repr__(self) -> str:
        return f"MeasuredDisturbances({self.model!r}, {list(self.measured_disturbances)})"


def _replace_arg(args: tuple, i: int, value: FloatArray) -> tuple:
    return args[:i] + (value,) + args[i + 1 :]


def _jacobian(f, z0: FloatArray, eps: float) -> FloatArray:
    """Central-difference Jacobian of ``f`` at ``z0``, evaluated in one vectorised call."""
    n = z0.size
    steps = eps * np.maximum(1.0, np.abs(z0))
    perturbed = np.concatenate([z0 + np.diag(steps), z0 - np.diag(steps)])
    values = f(perturbed)
    return ((values[:n] - values[n:]) / (2 * steps[:, None])).T
