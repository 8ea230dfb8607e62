"""Output error: the model simulated freely over whole recordings, the test model tests are
judged by.

Start the model where each record starts, drive it with the recorded inputs and compare the
whole time history of the measured channels. A model that is right only over a few seconds (a
yaw model against a 20-s time constant, a damping right at one amplitude) fails this test, and
parameters that only the whole history holds (a natural frequency and damping seen through the
roll angle alone) are fitted by it.

* :class:`Series` - one or several recordings of one vehicle on a common time step, resampled
  to the model's bandwidth so the answer does not depend on the recorder's sample rate.
* :class:`Structure` - what is fitted: named model parameters, coefficients of catalogue terms
  and the initial states; its free simulations are batched over parameter sets (one simulation
  gives the cost and its whole Jacobian).
* :func:`fit` - bounded trust-region least squares (scipy ``least_squares``) with standard
  errors from the residuals' effective number of independent samples.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import optimize, signal

from marine_envs import compiled
from marine_envs.compiled import first_use, jit
from marine_envs.models import VehicleModel
from marine_envs.models.effects import Effect, applied_inputs, state_term
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording

from .residuals import ANGLES, displacements, model_inputs, observable_states, white_noise_std

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: The internal time step resolves the fastest relevant motion with this many steps per radian.
STEPS_PER_RADIAN = 4.0
#: A residual this large (in signal scales) means the simulation diverged.
DIVERGED = 1e3


# -- the data -------------------------------------------------------------------------------------
@dataclass
class Run:
    """One recording on the series' time step.

    :param name: label (file name).  :param time: ``(T,)`` s from the record's start.
    :param u: commanded inputs ``(T, n_u)``, held between samples.  :param y: the measured
        channels ``(T, m)`` (angles unwrapped).  :param noise: their white-noise std.
    :param record: the recording a window was cut from (its index in the series' recordings;
        held-out scores leave a whole recording out), or None: the run is a recording.
    """

    name: str
    time: FloatArray
    u: FloatArray
    y: FloatArray
    noise: FloatArray
    record: int | None = None

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])


@dataclass
class Series:
    """Recordings of one vehicle with the same channels, on one time step ``dt``.

    :param scale: per channel, the RMS of the measured signal about its mean over all runs:
        residuals are measured in it, so channels of different units weigh alike.
    :param moving: per input, whether it moves in any run.
    """

    model: VehicleModel
    channels: tuple[str, ...]
    runs: list[Run]
    dt: float
    substeps: int
    scale: FloatArray
    moving: BoolArray
    #: :meth:`excited`, once worked out (every fit asks for it, and a model without exact
    #: matrices linearises by finite differences: a quarter of the hovercraft runs' diagnosis)
    _excited: BoolArray | None = field(default=None, init=False, repr=False)

    @classmethod
    def from_recordings(cls, recordings: Sequence[Recording], model: VehicleModel,
                        names: Sequence[str] = ()) -> Series:
        """The recordings resampled to the model's bandwidth (anti-aliased decimation by the
        largest integer factor that keeps :data:`STEPS_PER_RADIAN` steps per radian of the
        fastest of: the record's own oscillation, the inputs' slew, and the model's modes, at
        its nominal parameters and with ``names`` doubled and halved).

        :raises ValueError: recordings that measure different channels or have different
            sample periods.
        """
        channels = recordings[0].measured_names
        for rec in recordings[1:]:
            if rec.measured_names != channels:
                raise ValueError(f"all recordings of a series must measure the same channels; "
                                 f"{rec.measured_names} differs from {channels}")
        dt = recordings[0].dt
        if any(abs(r.dt / dt - 1) > 1e-3 for r in recordings):
            raise ValueError("all recordings of a series must have one sample period; got "
                             + ", ".join(f"{r.dt:g} s" for r in recordings))
        omega = max([_record_bandwidth(r) for r in recordings] + [_model_bandwidth(model, names)])
        factor = max(1, int(1 / (STEPS_PER_RADIAN * omega * dt)))
        runs = [_run(r, model, channels, factor) for r in recordings]
        y = np.concatenate([r.y for r in runs])
        scale = np.maximum(np.std(y, axis=0), 1e-9)
        moving = np.array([any(np.ptp(r.u[:, j]) > 0 for r in runs)
                           for j in range(len(model.input_names))], dtype=bool)
        h = dt * factor
        substeps = max(1, math.ceil(_model_bandwidth(model, names) * h / 0.5))
        return cls(model, tuple(channels), runs, h, substeps, scale, moving)

    def folds(self) -> list[list[int]]:
        """The runs held out together: each recording's windows (:attr:`Run.record`), or each
        run alone when they are whole recordings or cut from one."""
        records = [r.record for r in self.runs]
        if None in records or len(set(records)) < 2:
            return [[k] for k in range(len(self.runs))]
        return [[k for k, r in enumerate(records) if r == record]
                for record in dict.fromkeys(records)]

    def excited(self) -> BoolArray:
        """Per state: moved by an input that moves or by a measured state (through the
        linearised model's couplings), and seen by the measured channels."""
        if self._excited is None:
            self._excited = self._reached()
        return self._excited.copy()

    def _reached(self) -> BoolArray:
        A, B, _ = self.model.linearize()
        reach = np.array([s in self.channels for s in self.model.state_names])
        reach |= np.any(B[:, self.moving] != 0, axis=1)
        while True:
            more = reach | np.any(A[:, reach] != 0, axis=1)
            if (more == reach).all():
                break
            reach = more
        return reach & observable_states(self.model, self.channels)

    def force_states(self) -> list[int]:
        """Excited states whose equations carry forces (not kinematics)."""
        kinematic = displacements(self.model)
        return [i for i in np.flatnonzero(self.excited()) if i not in kinematic]


def _run(recording: Recording, model: VehicleModel, channels: Sequence[str], factor: int) -> Run:
    y = recording.measurements.copy()
    for j, name in enumerate(channels):
        if name in ANGLES:
            y[:, j] = np.unwrap(y[:, j])
    noise = white_noise_std(y)
    u, time = model_inputs(recording, model), recording.time - recording.time[0]
    if factor > 1:
        n = len(time) // factor * factor
        y = signal.resample_poly(y[:n], 1, factor, axis=0, padtype="line")
        u = u[:n].reshape(-1, factor, u.shape[1]).mean(axis=1)  # the held input's mean
        time = time[:n:factor]
        noise = noise / math.sqrt(factor)
    name = str(recording.meta.get("source_file", recording.meta.get("name", "")))
    return Run(name, time, u, y, noise)


def _record_bandwidth(recording: Recording) -> float:
    """The fastest motion in the record, rad/s: the spectral peak of the measured channels'
    rates (their oscillation) and the inputs' largest slew relative to their range."""
    dt = recording.dt
    omegas = [0.05]
    for y in recording.measurements.T:
        rate = np.diff(y) / dt
        f, psd = signal.periodogram(rate - rate.mean(), fs=1 / dt)
        if psd.sum() > 0:  # the peak, not the centroid: sensor noise must not move it
            omegas.append(2 * math.pi * float(f[np.argmax(psd)]))
    for u in recording.inputs.T:
        span = float(np.ptp(u))
        if span > 0:
            omegas.append(float(np.quantile(np.abs(np.diff(u)), 0.99)) / dt / (0.5 * span))
    return max(omegas)


def _model_bandwidth(model: VehicleModel, names: Sequence[str]) -> float:
    """The fastest mode of the linearised model, at its parameters and with each of ``names``
    doubled and halved (where calibration may take it)."""
    models = [model]
    for name in names:
        value = float(getattr(model.params, name))
        for factor in (0.5, 2.0):
            try:
                models.append(model.with_params(**{name: value * factor}))
            except ValueError:
                continue
    return max(float(np.max(np.abs(np.linalg.eigvals(m.linearize()[0])), initial=0.0))
               for m in models)


# -- what is fitted -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Structure:
    """A model to fit: the series' model with ``names`` free, ``terms`` (catalogue state effects
    or sensor biases, each with a free coefficient ``c`` or ``b``), fixed ``inputs`` effects,
    and the initial value of every excited state of every run.

    The unknowns ``theta`` are ordered: ``names``, the terms' coefficients, then each run's
    free initial states.
    """

    series: Series
    names: tuple[str, ...] = ()
    terms: tuple[Effect, ...] = ()
    inputs: tuple[Effect, ...] = ()

    @property
    def free_states(self) -> list[int]:
        return [int(i) for i in np.flatnonzero(self.series.excited())]

    @property
    def size(self) -> int:
        return len(self.names) + len(self.terms) + len(self.series.runs) * len(self.free_states)

    def labels(self) -> list[str]:
        """A name per unknown."""
        states = [self.series.model.state_names[i] for i in self.free_states]
        return [*self.names, *(term_label(t) for t in self.terms),
                *(f"{s}0[{r}]" for r in range(len(self.series.runs)) for s in states)]

    def start(self, values: Mapping[str, float] | None = None) -> FloatArray:
        """Unknowns at the model's values (or ``values`` by label), terms at zero and initial
        states at the first measured sample (the model's equilibrium where unmeasured)."""
        model, labels = self.series.model, self.labels()
        theta = np.zeros(self.size)
        theta[: len(self.names)] = [float(getattr(model.params, n)) for n in self.names]
        k = len(self.names) + len(self.terms)
        for run in self.series.runs:
            for i in self.free_states:
                name = model.state_names[i]
                theta[k] = (run.y[0, self.series.channels.index(name)]
                            if name in self.series.channels else model.x0[i])
                k += 1
        for label, value in (values or {}).items():
            if label in labels:
                theta[labels.index(label)] = value
        return theta

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Bounds of the unknowns (:func:`parameter_bounds` for the parameters; the rest
        free)."""
        low = np.full(self.size, -np.inf)
        low[:len(self.names)] = parameter_bounds(self.series.model, self.names)[0]
        return low, np.full(self.size, np.inf)

    def simulate(self, theta: FloatArray, run: int, steps: int | None = None,
                 actuators: Sequence[Sequence[Effect]] | None = None) -> FloatArray:
        """Measured channels ``(B, T, m)`` of the free simulations with unknowns ``theta``
        ``(B, P)`` over run ``run`` (its first ``steps`` samples); ``actuators`` gives each row
        input effects of its own, after the structure's (one simulation for a whole grid)."""
        series, model = self.series, self.series.model
        theta = np.atleast_2d(theta)
        n_names, n_terms = len(self.names), len(self.terms)
        coefficients = theta[:, n_names:n_names + n_terms]
        free = self.free_states
        start = n_names + n_terms + run * len(free)
        x = np.tile(model.x0, (theta.shape[0], 1))
        x[:, free] = theta[:, start:start + len(free)]
        data = series.runs[run]
        u = data.u
        for effect in self.inputs:
            u = applied_inputs(effect, model, u, series.dt)
        u = u[None] if actuators is None else \
            np.stack([_applied(model, u, row, series.dt) for row in actuators])
        steps = len(data.time) if steps is None else steps
        values = {n: theta[:, k] for k, n in enumerate(self.names)}
        states = _compiled_states(model, values, x, u[:, :steps], coefficients, self.terms,
                                  series.dt / series.substeps, series.substeps, steps)
        if states is None:
            states = self._numpy_states(values, x, u, coefficients, run, steps)
        channel_index = [model.output_names.index(c) for c in series.channels]
        with np.errstate(all="ignore"):  # a wild trial value may overflow: caught below
            out = model.output(states)[..., channel_index]
        for j, term in enumerate(self.terms):
            if term.kind == "output":
                out[:, :, series.channels.index(term.target)] += coefficients[:, j, None]
        return out

    def _numpy_states(self, values: Mapping[str, FloatArray], x: FloatArray, u: FloatArray,
                      coefficients: FloatArray, run: int, steps: int) -> FloatArray:
        """States ``(B, steps, n_x)`` of :meth:`simulate` stepped by numpy (a model without
        compiled equations, or a term the compiled simulation does not know)."""
        series, model = self.series, self.series.model
        affine = _affine(model, values, x.shape[0])
        u = np.broadcast_to(u, (x.shape[0], *u.shape[1:]))
        states = [(k, t, model.state_names.index(t.target)) for k, t in enumerate(self.terms)
                  if t.kind == "state"]
        out = np.empty((x.shape[0], steps, x.shape[1]))
        h = series.dt / series.substeps
        time = series.runs[run].time
        with np.errstate(all="ignore"):  # a wild trial value may overflow: caught later
            for k in range(steps):
                out[:, k] = x
                uk = u[:, k]
                forced = affine.forced(uk)

                def f(z: FloatArray, t: float, uk: FloatArray = uk,
                      forced: FloatArray = forced) -> FloatArray:
                    z_dot = affine.rhs(z, forced)
                    for j, term, i in states:
                        z_dot[:, i] += coefficients[:, j] * state_term(term, model, z, uk, t)
                    return z_dot

                x = rk4(f, x, h, series.substeps, t=float(time[k]))
        return out

    def residuals(self, theta: FloatArray, rows: Sequence[BoolArray | None],
                  actuators: Sequence[Sequence[Effect]] | None = None) -> FloatArray:
        """Residuals ``(B, L)`` in signal scales, each run's selected samples weighted so its
        mean square counts once (runs alike; the sample rate does not matter); runs whose
        ``rows`` entry is None are skipped; ``actuators`` as in :meth:`simulate`."""
        series = self.series
        used = [r for r, mask in enumerate(rows) if mask is not None]
        parts = []
        for r in used:
            mask = rows[r]
            last = int(np.flatnonzero(mask)[-1]) + 1
            simulated = self.simulate(theta, r, last, actuators)[:, mask[:last]]
            error = (simulated - series.runs[r].y[mask]) / series.scale
            weight = 1 / math.sqrt(max(int(mask.sum()), 1) * len(series.channels) * len(used))
            parts.append(error.reshape(error.shape[0], -1) * weight)
        out = np.concatenate(parts, axis=1)
        return np.clip(np.nan_to_num(out, nan=DIVERGED), -DIVERGED, DIVERGED)


def _applied(model: VehicleModel, u: FloatArray, effects: Sequence[Effect],
             dt: float) -> FloatArray:
    for effect in effects:
        u = applied_inputs(effect, model, u, dt)
    return u


def term_label(term: Effect) -> str:
    """``effect(target)`` (with its source or form where it has one)."""
    source = term.parameters.get("source")
    return f"{term.effect}({term.target}{', ' + source if source else ''})"


def basis(effect: str, target: str, **text: str) -> Effect:
    """A catalogue term with unit coefficient (its coefficient is an unknown of a fit)."""
    key = "b" if effect in ("current", "sensor_bias") else "c"
    return Effect(effect, target, {key: 1.0, **text})


#: The state terms the compiled simulation knows, by code: ``c`` times ``1``, ``x``, ``x|x|``,
#: ``x^3`` of the target, ``x`` and ``x^3`` of the source (:func:`~marine_envs.models.effects.
#: state_term`).
_TERM_CODES = {"current": 0, "linear_damping": 1, "quadratic_damping": 2,
               "nonlinear_damping": 3, "coupling": 4, "nonlinear_restoring": 5}


def _compiled_states(model: VehicleModel, values: Mapping[str, FloatArray], x: FloatArray,
                     u: FloatArray, coefficients: FloatArray, terms: Sequence[Effect],
                     h: float, substeps: int, steps: int) -> FloatArray | None:
    """States ``(B, steps, n_x)`` of free simulations from ``x`` ``(B, n_x)`` driven by ``u``
    ``(1 or B, steps, n_u)``, integrated by the model's compiled equations (the same RK4 as
    :func:`~marine_envs.models.integrate.rk4`, one boat at a time: the numpy path's twenty
    small array operations per step were 98 % of the three-zigzag series' diagnosis, 69 s
    of CPU, now 4 s); None when the model has no compiled equations, cannot pack a parameter
    set per row or a term is not in :data:`_TERM_CODES`."""
    if type(model).equations is None or type(model).rhs is not VehicleModel.rhs:
        return None
    state_terms = [t for t in terms if t.kind == "state"]
    if any(t.effect not in _TERM_CODES for t in state_terms):
        return None
    constants = _row_constants(model, values)
    if constants is None:
        return None
    names = model.state_names
    code = np.array([[_TERM_CODES[t.effect], names.index(t.target),
                      names.index(t.parameters.get("source", t.target))]
                     for t in state_terms], dtype=np.int64).reshape(-1, 3)
    unit = np.array([float(t.parameters.get("c", t.parameters.get("b", 1.0)))
                     for t in state_terms])
    which = [k for k, t in enumerate(terms) if t.kind == "state"]
    scaled = np.ascontiguousarray(coefficients[:, which] * unit, dtype=float)
    out = np.empty((x.shape[0], steps, x.shape[1]))
    kernel = _free_runs(type(model).equations.core)
    with first_use(f"{model.name} free simulation"):
        kernel(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(u, dtype=float),
               np.zeros(len(model.disturbance_names)), constants, code, scaled, h, substeps,
               out)
    return out


def _row_constants(model: VehicleModel, values: Mapping[str, FloatArray]) -> FloatArray | None:
    """The model's packed constants with ``values`` ``{name: (B,)}``: ``(1, p)`` without
    values, else ``(B, p)``; None when a row's values are not a model."""
    if not values:
        return np.atleast_2d(model.constants).astype(float)
    if model.row_parameters:
        packed = model.with_rows(**values).constants
        rows = len(next(iter(values.values())))
        return np.ascontiguousarray(np.broadcast_to(packed, (rows, packed.shape[-1])),
                                    dtype=float)
    try:
        return np.array([model.with_params(**dict(zip(values, row, strict=True))).constants
                         for row in zip(*(v.tolist() for v in values.values()), strict=True)])
    except ValueError:
        return None


@functools.cache
def _free_runs(core: Callable[..., None]) -> Callable[..., None]:
    """The compiled free simulations of a model's equations ``core(x, u, d, p, out)``:
    ``f(X0, U, D, P, code, C, h, substeps, OUT)`` writes to ``OUT[b, k]`` the state of row
    ``b`` at sample ``k`` (from ``X0[b]``, inputs ``U[b or 0, k]`` held over each sample,
    constants ``P[b or 0]``, the terms ``code`` (kind, target, source) with coefficients
    ``C[b]``), each sample ``substeps`` steps of :func:`marine_envs.compiled.rk4`, the
    environments' integrator. Made once per process, compiled once per machine."""
    advance = compiled.rk4(_with_terms(core))

    @jit
    def free_runs(X0, U, D, P, code, C, h, substeps, OUT):
        work = np.empty((3, X0.shape[1]))
        for b in range(X0.shape[0]):
            terms = (P[0] if P.shape[0] == 1 else P[b], code, C[b])
            inputs = U[0] if U.shape[0] == 1 else U[b]
            for k in range(OUT.shape[1]):  # (no sample: nothing written)
                if k == 0:
                    for i in range(X0.shape[1]):
                        OUT[b, 0, i] = X0[b, i]
                else:
                    advance(OUT[b, k - 1], inputs[k - 1], D, terms, h, substeps, OUT[b, k], work)

    return free_runs


def _with_terms(core: Callable[..., None]) -> Callable[..., None]:
    """``core`` with catalogue state terms added to its derivative: ``f(x, u, d, terms, out)``
    with ``terms = (p, code, c)``, the model's constants ``p`` and the terms ``code`` (kind,
    target, source; :data:`_TERM_CODES`) with coefficients ``c``."""

    @jit
    def with_terms(x, u, d, terms, out):
        p, code, c = terms
        core(x, u, d, p, out)
        for j in range(code.shape[0]):
            target, source = x[code[j, 1]], x[code[j, 2]]
            kind = code[j, 0]
            if kind == 0:
                term = 1.0
            elif kind == 1:
                term = target
            elif kind == 2:
                term = target * abs(target)
            elif kind == 3:
                term = target**3
            elif kind == 4:
                term = source
            else:
                term = source**3
            out[code[j, 1]] += c[j] * term

    return with_terms


class _affine:
    """The model's ``rhs`` with a parameter set per batch row, split as ``rhs(x, forced(u))``.
    A linear model becomes its matrices, read off ``rhs`` exactly (``A x + B u + c`` per row:
    a few array operations per call instead of the model's dozens)."""

    def __init__(self, model: VehicleModel, values: Mapping[str, FloatArray],
                 batch: int) -> None:
        if not values:
            self._rhs = model.rhs
        elif model.row_parameters:
            self._rhs = model.with_rows(**values).rhs
        else:
            self._rhs = lambda x, u: model.rhs_with(x, u, None, values)
        self.matrices = None
        if model.is_linear:
            n, m = len(model.state_names), len(model.input_names)
            x0, u0 = np.zeros((batch, n)), np.zeros((batch, m))
            c = self._rhs(x0, u0)
            A = np.stack([self._rhs(x0 + e, u0) - c for e in np.eye(n)], axis=-1)
            B = np.stack([self._rhs(x0, u0 + e) - c for e in np.eye(m)], axis=-1)
            self.matrices = (A, B, c)

    def forced(self, u: FloatArray) -> FloatArray:
        """What the input contributes: ``B u + c`` (linear), or the input itself."""
        if self.matrices is None:
            return u
        _, B, c = self.matrices
        return np.einsum("bij,bj->bi", B, u) + c

    def rhs(self, x: FloatArray, forced: FloatArray) -> FloatArray:
        if self.matrices is None:
            return self._rhs(x, forced)
        return np.einsum("bij,bj->bi", self.matrices[0], x) + forced


def parameter_bounds(model: VehicleModel, names: Sequence[str]) -> tuple[FloatArray, FloatArray]:
    """Bounds for fitting ``names``: a parameter the model refuses to make negative (or zero)
    stays positive; the rest are free."""
    low = np.full(len(names), -np.inf)
    for k, name in enumerate(names):
        value = float(getattr(model.params, name))
        if value > 0 and not _accepts(model, name, -value):
            low[k] = 0.0 if _accepts(model, name, 0.0) else value * 1e-6
    return low, np.full(len(names), np.inf)


def _accepts(model: VehicleModel, name: str, value: float) -> bool:
    try:
        model.with_params(**{name: value})
    except ValueError:
        return False
    return True


# -- fitting --------------------------------------------------------------------------------------
@dataclass
class Fit:
    """A least-squares fit of a structure.

    :param theta: the unknowns.  :param cost: mean square residual (signal scales).
    :param std: standard deviations of the unknowns (from the effective sample count).
    :param correlation: their correlation matrix.  :param converged: the solver's verdict.
    """

    structure: Structure
    theta: FloatArray
    cost: float
    std: FloatArray
    correlation: FloatArray
    converged: bool
    message: str
    jacobian: FloatArray = field(repr=False)

    def values(self) -> dict[str, float]:
        return dict(zip(self.structure.labels(), self.theta.tolist(), strict=True))


def fit(structure: Structure, rows: Sequence[BoolArray | None],
        theta0: FloatArray | None = None, fixed: Sequence[int] = ()) -> Fit:
    """Fit the unknowns of ``structure`` to the selected samples (bounded trust region, exact
    batched central-difference Jacobian, a lag's gain and time constant moved as
    :class:`Coordinates`); ``fixed`` unknowns keep their ``theta0`` values."""
    theta0 = structure.start() if theta0 is None else np.asarray(theta0, dtype=float)
    free = np.setdiff1d(np.arange(structure.size), np.asarray(fixed, dtype=int))
    if not free.size:
        r = structure.residuals(theta0[None], rows)[0]
        return Fit(structure, theta0, float(r @ r), np.zeros(0), np.zeros((0, 0)), True, "",
                   np.zeros((0, 0)))
    coordinates = Coordinates(structure.series.model, structure.labels(), free.tolist())
    low, high = structure.bounds()
    start = theta0.copy()
    start[free] = np.clip(theta0[free], low[free], high[free])
    z_start = coordinates.solver(start)
    low, high = coordinates.bounds(low, high)
    cache: dict[bytes, tuple[FloatArray, FloatArray]] = {}

    def full(z: FloatArray) -> FloatArray:
        out = z_start.copy()
        out[free] = z
        return out

    def evaluate(z: FloatArray) -> tuple[FloatArray, FloatArray]:
        key = z.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = jacobian(structure, coordinates.unknowns(full(z)), rows, free,
                                  coordinates)
        return cache[key]

    z0 = np.clip(z_start[free], low[free], high[free])
    result = optimize.least_squares(lambda z: evaluate(z)[0], z0, jac=lambda z: evaluate(z)[1],
                                    bounds=(low[free], high[free]), method="trf",
                                    x_scale="jac", max_nfev=60, ftol=1e-6, xtol=1e-6)
    r, J_solver = evaluate(result.x)
    theta = coordinates.unknowns(full(result.x))
    J = J_solver @ coordinates.derivative(theta)[np.ix_(free, free)]  # per unknown
    std, correlation = _covariance(r, J, structure, rows)
    std_full = np.zeros(structure.size)
    std_full[free] = std
    corr_full = np.eye(structure.size)
    corr_full[np.ix_(free, free)] = correlation
    return Fit(structure, theta, float(r @ r), std_full, corr_full,
               bool(result.success and np.all(np.abs(r) < DIVERGED)), result.message, J)


class Coordinates:
    """The unknowns as the solver moves them: a model's lag time constant ``T`` as ``1/T`` and,
    when free with it, the lag's gain ``K`` as ``K/T`` (:attr:`VehicleModel.lag_parameters`);
    every other unknown as itself. ``K/T`` and ``1/T`` are the coefficients of the equation,
    smooth where the lag turns unstable: a fit can cross from a stable ship to a course-unstable
    one (``T`` through infinity, where ``K`` and ``T`` alone are undefined)."""

    #: ``|1/T|`` is kept above this (1/s): ``T`` stays finite.
    SMALLEST_RATE = 1e-12

    def __init__(self, model: VehicleModel, labels: Sequence[str], free: Sequence[int]) -> None:
        """``labels``: a name per unknown; ``free``: the positions the solver moves."""
        lag, labels = model.lag_parameters, list(labels)
        index = {n: labels.index(n) for n in lag or () if n in labels and labels.index(n) in free}
        self.t = index.get(lag[1]) if lag else None
        self.k = index.get(lag[0]) if lag and self.t is not None else None

    def solver(self, theta: FloatArray) -> FloatArray:
        """The solver's coordinates of unknowns ``theta`` (``(..., P)``)."""
        z = np.array(theta, dtype=float)
        if self.t is not None:
            z[..., self.t] = 1 / theta[..., self.t]
            if self.k is not None:
                z[..., self.k] = theta[..., self.k] / theta[..., self.t]
        return z

    def unknowns(self, z: FloatArray) -> FloatArray:
        """The unknowns at solver coordinates ``z`` (``(..., P)``)."""
        theta = np.array(z, dtype=float)
        if self.t is not None:
            rate = z[..., self.t]
            rate = np.where(np.abs(rate) < self.SMALLEST_RATE,
                            np.copysign(self.SMALLEST_RATE, rate), rate)
            theta[..., self.t] = 1 / rate
            if self.k is not None:
                theta[..., self.k] = z[..., self.k] / rate
        return theta

    def derivative(self, theta: FloatArray) -> FloatArray:
        """``dz/dtheta`` ``(P, P)`` at unknowns ``theta`` (a solver Jacobian times it is the
        Jacobian per unknown)."""
        D = np.eye(len(theta))
        if self.t is not None:
            t = theta[self.t]
            D[self.t, self.t] = -1 / t**2
            if self.k is not None:
                D[self.k, self.k] = 1 / t
                D[self.k, self.t] = -theta[self.k] / t**2
        return D

    def bounds(self, low: FloatArray, high: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Bounds in solver coordinates: a positive ``T`` keeps ``1/T`` (and, with ``K``
        positive, ``K/T``) positive; otherwise free."""
        low, high = low.copy(), high.copy()
        if self.t is None:
            return low, high
        positive = low[self.t] >= 0
        low[self.t], high[self.t] = (0.0 if positive else -np.inf), np.inf
        if self.k is not None:
            low[self.k] = 0.0 if positive and low[self.k] >= 0 else -np.inf
            high[self.k] = np.inf
        return low, high


def jacobian(structure: Structure, theta: FloatArray, rows: Sequence[BoolArray | None],
             free: NDArray[np.int_] | None = None, coordinates: Coordinates | None = None
             ) -> tuple[FloatArray, FloatArray]:
    """Residuals ``(L,)`` and their central-difference Jacobian ``(L, len(free))`` (default:
    every unknown; with respect to the ``coordinates``' solver coordinates when given) from one
    batched simulation."""
    free = np.arange(structure.size) if free is None else free
    z = theta if coordinates is None else coordinates.solver(theta)
    steps = 1e-6 * np.maximum(np.abs(z[free]), 1e-3)
    batch = np.tile(z, (1 + 2 * len(free), 1))
    for k, (i, s) in enumerate(zip(free, steps, strict=True)):
        batch[1 + 2 * k, i] += s
        batch[2 + 2 * k, i] -= s
    if coordinates is not None:
        batch = coordinates.unknowns(batch)
        batch[0] = theta
    r = structure.residuals(batch, rows)
    return r[0], ((r[1::2] - r[2::2]) / (2 * steps[:, None])).T


def _covariance(r: FloatArray, J: FloatArray, structure: Structure,
                rows: Sequence[BoolArray | None]) -> tuple[FloatArray, FloatArray]:
    """Standard deviations and correlations of the unknowns: ``cost (J'J)^-1 / (N_eff - P)``
    with ``N_eff`` the number of independent samples the residuals hold (their count over the
    integrated autocorrelation time): free-simulation errors are smooth, not white."""
    n_eff = sum(_effective_samples(structure, r_, mask) for r_, mask in _split(r, structure, rows))
    dof = max(n_eff - J.shape[1], 1.0)
    norms = np.linalg.norm(J, axis=0)
    scale = np.where(norms > 0, norms, 1.0)
    values, vectors = np.linalg.eigh((J / scale).T @ (J / scale))
    # a direction the residuals hardly change along (a combination the records do not hold)
    # has unbounded variance; pinv would report it as perfectly known
    null = values < 1e-10 * max(float(values[-1]), 1e-300)
    inverse = np.where(null, 0.0, 1 / np.where(null, 1.0, values))
    covariance = (vectors * inverse) @ vectors.T / np.outer(scale, scale) * float(r @ r) / dof
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    unseen = (norms == 0) | np.any(np.abs(vectors[:, null]) > 1e-3, axis=1)
    std[unseen] = np.inf
    finite = np.where(np.isfinite(std) & (std > 0), std, 1.0)
    correlation = covariance / np.outer(finite, finite)
    correlation[unseen] = 0.0
    correlation[:, unseen] = 0.0
    np.fill_diagonal(correlation, 1.0)
    return std, np.clip(correlation, -1.0, 1.0)


def _split(r: FloatArray, structure: Structure, rows: Sequence[BoolArray | None]):
    m, k = len(structure.series.channels), 0
    for mask in rows:
        if mask is None:
            continue
        n = int(mask.sum()) * m
        yield r[k:k + n].reshape(-1, m), mask
        k += n


def _effective_samples(structure: Structure, r: FloatArray, mask: BoolArray) -> float:
    """Samples over the integrated autocorrelation time of the residuals (per channel, the
    slowest), so that resampling a record does not change its evidence."""
    tau = 1.0
    for e in r.T:
        e = e - e.mean()
        if not np.any(e):
            continue
        acf = signal.correlate(e, e, mode="full", method="fft")[len(e) - 1:]
        acf = acf / acf[0]
        stop = int(np.argmax(acf < 0)) or len(acf)
        tau = max(tau, 1 + 2 * float(np.sum(acf[1:stop])))
    return len(r) / tau
