"""Parameter identification of vehicle models from manoeuvre data (seed 004, reusable).

Model-agnostic: everything works on a :class:`~marine_envs.models.VehicleModel` (its ``rhs_with``
and ``parameter_jacobian``), the names of the parameters to identify (fields of ``model.params``)
and data: one or several :class:`Segment` s (runs) of inputs and measurements. Three methods:

* :func:`identify_ekf`: the parameters appended to the state of an extended Kalman filter
  (:class:`~estimators.ekf.ExtendedKalmanFilter`), seed 004's method. Several segments run as a
  batch of filters from the same prior and their parameter posteriors are fused (product of the
  Gaussian likelihoods); :func:`identify_staged` chains stages (e.g. linear coefficients from a
  mild manoeuvre, then the nonlinear ones from harder ones).
* :func:`identify_least_squares` with ``method="equation_error"``: the accelerations
  (Savitzky-Golay derivatives of the measurements) regressed on ``d rhs / d theta``; exact in one
  step for parameters in which ``rhs`` is affine, Gauss-Newton otherwise. Needs no initial guess
  of the parameters, but every state the fitted equations use must be measured.
* :func:`identify_least_squares` with ``method="output_error"``: simulated outputs fitted to the
  measured ones (``scipy.optimize.least_squares``), initial states included. The maximum-likelihood
  fit when the only noise is the sensors', but one simulation of every segment per parameter and
  iteration.

Every method returns an :class:`Identification`: estimates, standard deviations, correlations, and
a verdict per parameter from the information matrix ``I`` of the data, in units of each
parameter's scale (the prior std for the EKF, where ``I`` is what the data added to the prior; the
magnitude of the initial value for least squares). A parameter is *not identifiable* when

* it shares a numerically null direction of ``I`` with others: collinear, only a combination is
  determined (least squares then reports an infinite std);
* even with all the others known, the data would leave its std above ``max_relative_std`` of its
  scale (``I_ii < max_relative_std**-2``): no excitation;
* (EKF) it shares a direction in which the data add less information than the prior with others;
* or its std is above ``max_relative_std`` of its scale.

Damping coefficients with the energy-injecting sign are flagged (:func:`damping_signs`).

Data convention (as :meth:`~estimators.ekf.ExtendedKalmanFilter.filter`): ``inputs[k]`` is held
from ``time[k]`` to ``time[k + 1]``; ``measurements[k]`` is taken at ``time[k]``. SI units,
radians; NaN is not allowed (drop or interpolate missing samples first).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.optimize
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel

from .ekf import ExtendedKalmanFilter, FilterResult, rts_smooth

FloatArray = NDArray[np.float64]
#: Fewest samples a segment may have.
MIN_SAMPLES = 10
#: A direction of the scaled information matrix with an eigenvalue below this fraction of the
#: largest is taken as not excited (numerically rank deficient).
NULL_TOLERANCE = 1e-10
#: Force/moment letter -> its own velocity (SNAME): X_u, Y_v, Z_w, K_p, M_q, N_r are damping.
_OWN_VELOCITY = {"X": "u", "Y": "v", "Z": "w", "K": "p", "M": "q", "N": "r"}


# -- data ---------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Segment:
    """One run of a vehicle: inputs and measurements on a uniform time grid.

    :param time: sample times ``(T,)``, s, strictly increasing with a uniform step.
    :param inputs: model inputs ``(T, n_u)`` in the model's units; row ``k`` is held until
        ``time[k + 1]``.
    :param measurements: measured channels ``(T, m)``, named by ``measured``.
    :param measured: the channels, names of ``model.output_names``.
    :param disturbance: model disturbance, ``(n_d,)`` constant or ``(T, n_d)``; None = zero.
    :param x0: initial state guess ``(n_x,)``; None = the model's nominal state with the measured
        states replaced by their first sample.
    :param angular: measured channels that are angles (possibly wrapped), rad.
    :param name: a label for reports (e.g. ``"5/5"``).
    """

    time: FloatArray
    inputs: FloatArray
    measurements: FloatArray
    measured: tuple[str, ...]
    disturbance: FloatArray | None = None
    x0: FloatArray | None = None
    angular: tuple[str, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        label = f"segment {self.name!r}" if self.name else "segment"
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        time = _finite_array(f"{label} time", self.time, 1)
        T = time.shape[0]
        if T < MIN_SAMPLES:
            raise ValueError(f"{label} has {T} samples; at least {MIN_SAMPLES} are needed")
        step = np.diff(time)
        if not (step > 0).all():
            raise ValueError(f"{label} time must be strictly increasing (row "
                             f"{int(np.argmax(step <= 0)) + 1})")
        if np.abs(step - step.mean()).max() > 1e-6 * step.mean():
            raise ValueError(f"{label} time step is not uniform ({step.min():g} to "
                             f"{step.max():g} s); resample first")
        set_("time", time)
        set_("measured", (self.measured,) if isinstance(self.measured, str)
             else tuple(self.measured))
        set_("angular", tuple(self.angular))
        for key, width in (("inputs", None), ("measurements", len(self.measured))):
            a = _finite_array(f"{label} {key}", getattr(self, key), 2)
            if a.shape[0] != T:
                raise ValueError(f"{label} {key} has {a.shape[0]} rows but time has {T}")
            if width is not None and a.shape[1] != width:
                raise ValueError(f"{label} measurements have {a.shape[1]} columns but "
                                 f"{width} channels are named ({', '.join(self.measured)})")
            set_(key, a)
        if self.disturbance is not None:
            d = _finite_array(f"{label} disturbance", self.disturbance, None)
            if d.ndim == 2 and d.shape[0] != T:
                raise ValueError(f"{label} disturbance has {d.shape[0]} rows but time has {T}")
            set_("disturbance", d)
        if self.x0 is not None:
            set_("x0", _finite_array(f"{label} x0", self.x0, 1))
        unknown = sorted(set(self.angular) - set(self.measured))
        if unknown:
            raise ValueError(f"{label} angular channel(s) {unknown} are not measured")

    @property
    def dt(self) -> float:
        """Sampling period, s."""
        return float(self.time[1] - self.time[0])

    @property
    def label(self) -> str:
        return f"segment {self.name!r}" if self.name else "segment"

    @classmethod
    def from_recording(cls, recording: Any, name: str = "",
                       angular: Sequence[str] = ()) -> Segment:
        """A segment from a :class:`~marine_envs.recording.Recording` (SI units)."""
        return cls(recording.time, recording.inputs, recording.measurements,
                   recording.measured_names, angular=tuple(angular), name=name)

    def unwrapped(self) -> FloatArray:
        """The measurements with the angular channels unwrapped, ``(T, m)``."""
        y = self.measurements.copy()
        for c in self.angular:
            j = self.measured.index(c)
            y[:, j] = np.unwrap(y[:, j])
        return y


def _finite_array(name: str, value: ArrayLike, ndim: int | None) -> FloatArray:
    a = np.asarray(value, dtype=float)
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        where = np.argwhere(bad)[0]
        raise ValueError(f"{name} has {int(bad.sum())} non-finite value(s) (NaN or inf), first "
                         f"at index {tuple(int(i) for i in where)}; drop or interpolate them")
    return a


def as_segments(data: Segment | Sequence[Segment]) -> list[Segment]:
    """``data`` as a non-empty list of segments."""
    segments = [data] if isinstance(data, Segment) else list(data)
    if not segments or not all(isinstance(s, Segment) for s in segments):
        raise TypeError("data must be a Segment or a non-empty sequence of Segments")
    return segments


def noise_std(segment: Segment) -> FloatArray:
    """Measurement noise standard deviation of each channel ``(m,)``, estimated from the data:
    the spread of the second differences, which for white noise have variance ``6 sigma^2``
    while those of a smooth signal sampled fast are ~0; samples beyond 4 robust (MAD) standard
    deviations (input steps, outliers) are left out."""
    d2 = np.diff(segment.unwrapped(), 2, axis=0)
    centred = d2 - np.median(d2, axis=0)
    mad = np.median(np.abs(centred), axis=0) / 0.6745
    kept = np.where(np.abs(centred) <= 4 * mad, centred, np.nan)
    return np.sqrt(np.nanmean(kept**2, axis=0) / 6.0)


def _check_data(model: VehicleModel, segments: list[Segment]) -> None:
    """Segment contents against the model: channels, input and disturbance widths, one dt."""
    n_u, n_d = len(model.input_names), len(model.disturbance_names)
    for s in segments:
        unknown = sorted(set(s.measured) - set(model.output_names))
        if unknown:
            raise ValueError(f"{s.label}: measured channel(s) {unknown} are not outputs of model "
                             f"{model.name!r}: {', '.join(model.output_names)}")
        if s.inputs.shape[1] != n_u:
            raise ValueError(f"{s.label} inputs have {s.inputs.shape[1]} columns; model "
                             f"{model.name!r} has {n_u} ({', '.join(model.input_names)})")
        if s.disturbance is not None and s.disturbance.shape[-1] != n_d:
            raise ValueError(f"{s.label} disturbance has width {s.disturbance.shape[-1]}; "
                             f"model {model.name!r} has {n_d}")
        if s.x0 is not None and s.x0.shape != (len(model.state_names),):
            raise ValueError(f"{s.label} x0 has shape {s.x0.shape}; expected "
                             f"({len(model.state_names)},)")
    first = segments[0]
    for s in segments[1:]:
        if s.measured != first.measured:
            raise ValueError(f"{s.label} measures {s.measured} but {first.label} measures "
                             f"{first.measured}; identify from segments with the same channels")
        if not math.isclose(s.dt, first.dt, rel_tol=1e-6):
            raise ValueError(f"{s.label} has dt={s.dt:g} s but {first.label} has {first.dt:g} s")


def check_parameters(model: VehicleModel, parameters: Sequence[str]) -> tuple[str, ...]:
    """The parameter names, validated: known scalar fields of ``model.params``, no repeats.

    :raises ValueError: naming the unknown parameters and listing the known ones.
    """
    if isinstance(parameters, str):
        parameters = (parameters,)
    names = tuple(parameters)
    if not names:
        raise ValueError("no parameters to identify: give at least one name")
    scalars = [f.name for f in dataclasses.fields(model.params)
               if isinstance(getattr(model.params, f.name), int | float)
               and not isinstance(getattr(model.params, f.name), bool)]
    unknown = [n for n in names if n not in scalars]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for model {model.name!r}; known: "
                         f"{', '.join(scalars)}")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"parameter(s) {repeated} listed more than once")
    return names


def _values(model: VehicleModel, names: tuple[str, ...], given: Mapping[str, float] | None,
            what: str) -> FloatArray:
    """Per-parameter values from ``given`` (a mapping by name), default the model's own."""
    given = dict(given or {})
    extra = sorted(set(given) - set(names))
    if extra:
        raise ValueError(f"{what} names parameter(s) {extra} that are not identified here "
                         f"({', '.join(names)})")
    out = np.array([float(given.get(n, getattr(model.params, n))) for n in names])
    if not np.isfinite(out).all():
        raise ValueError(f"{what} has non-finite values: {dict(zip(names, out, strict=True))}")
    return out


def _scales(names: tuple[str, ...], initial: FloatArray, given: Mapping[str, float] | None,
            what: str = "prior_std") -> FloatArray:
    """Per-parameter scale (prior std): ``given`` by name, default ``|initial|``."""
    given = dict(given or {})
    extra = sorted(set(given) - set(names))
    if extra:
        raise ValueError(f"{what} names parameter(s) {extra} that are not identified here")
    out = np.array([float(given.get(n, abs(v))) for n, v in zip(names, initial, strict=True)])
    bad = [n for n, s in zip(names, out, strict=True) if not (math.isfinite(s) and s > 0)]
    if bad:
        raise ValueError(f"{what} of {bad} must be finite and > 0 (their initial value is 0: "
                         f"give {what}={{name: value}})")
    return out


# -- result -------------------------------------------------------------------------------------
@dataclasses.dataclass
class Identification:
    """Identified parameters with their uncertainty and a verdict on each.

    :param names: parameter names (fields of ``model.params``).
    :param estimate: estimates ``(p,)`` in the parameters' units.
    :param std: standard deviations ``(p,)`` (inf where not determined).
    :param correlation: correlation matrix ``(p, p)``.
    :param identifiable: ``(p,)`` whether the data determine each parameter.
    :param reason: ``(p,)`` why (or why not), for people.
    :param negative_damping: ``(p,)`` a damping coefficient estimated with the energy-injecting
        sign.
    :param method: ``"ekf"``, ``"equation_error"`` or ``"output_error"``.
    :param scale: ``(p,)`` the scale the verdict compares ``std`` with (prior std or magnitude).
    :param reference: ``(p,)`` true (or reference) values, if known.
    :param condition_number: of the scaled information matrix (1 = orthogonal, well excited).
    :param trace_time, trace, trace_std: the EKF estimates over time ``(K,)``, ``(K, p)``,
        ``(K, p)`` (time since the start of the segments; several segments fused).
    :param states: RTS-smoothed model states per segment ``(T_i, n_x)`` (EKF with ``smooth``).
    :param info: method details (iterations, NIS, segments, ...), JSON-serialisable.
    """

    names: tuple[str, ...]
    estimate: FloatArray
    std: FloatArray
    correlation: FloatArray
    identifiable: NDArray[np.bool_]
    reason: tuple[str, ...]
    negative_damping: NDArray[np.bool_]
    method: str
    scale: FloatArray
    reference: FloatArray | None = None
    condition_number: float = math.nan
    trace_time: FloatArray | None = None
    trace: FloatArray | None = None
    trace_std: FloatArray | None = None
    states: list[FloatArray] | None = None
    info: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def covariance(self) -> FloatArray:
        """Covariance matrix ``(p, p)``."""
        return self.correlation * np.outer(self.std, self.std)

    @property
    def rel_error(self) -> FloatArray | None:
        """``(estimate - reference) / |reference|`` ``(p,)`` (NaN where the reference is 0)."""
        if self.reference is None:
            return None
        ref = np.asarray(self.reference, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ref != 0, (self.estimate - ref) / np.abs(ref), np.nan)

    def as_dict(self) -> dict[str, float]:
        """``{name: estimate}``, e.g. for ``model.with_params(**result.as_dict())``."""
        return {n: float(v) for n, v in zip(self.names, self.estimate, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: per parameter ``estimate, std, rel_std, identifiable, reason,
        negative_damping`` (and ``true, rel_error`` with a reference); NaN/inf become None."""
        rel = self.rel_error
        params = {}
        for i, n in enumerate(self.names):
            entry = {"estimate": self.estimate[i], "std": self.std[i],
                     "rel_std": self.std[i] / self.scale[i],
                     "identifiable": bool(self.identifiable[i]), "reason": self.reason[i],
                     "negative_damping": bool(self.negative_damping[i])}
            if self.reference is not None and rel is not None:
                entry.update(true=self.reference[i], rel_error=rel[i])
            params[n] = {k: _json(v) for k, v in entry.items()}
        return {"method": self.method, "parameters": params,
                "condition_number": _json(self.condition_number),
                "correlation": [[_json(c) for c in row] for row in self.correlation],
                "info": self.info}

    def table(self) -> str:
        """A text table of the estimates."""
        rel = self.rel_error
        head = f"{'parameter':10} {'estimate':>12} {'std':>10} {'true':>12} {'error':>8}  verdict"
        lines = [head, "-" * len(head)]
        for i, n in enumerate(self.names):
            true = f"{self.reference[i]:12.4g}" if self.reference is not None else f"{'':12}"
            err = f"{rel[i]:+8.1%}" if rel is not None and np.isfinite(rel[i]) else f"{'':8}"
            verdict = "ok" if self.identifiable[i] else "NOT IDENTIFIABLE"
            if self.negative_damping[i]:
                verdict += ", NEGATIVE DAMPING"
            lines.append(f"{n:10} {self.estimate[i]:12.4g} {self.std[i]:10.3g} {true} {err}  "
                         f"{verdict}")
        return "\n".join(lines)


def _json(value: Any) -> Any:
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, str):
        return value
    value = float(value)
    return value if math.isfinite(value) else None


def damping_signs(names: Sequence[str]) -> dict[str, float]:
    """Expected sign (-1) of the damping coefficients among ``names``, by the SNAME convention:
    a force ``X, Y, Z`` or moment ``K, M, N`` coefficient whose derivative letters are all its own
    velocity (``X_u``, ``X_Huu``, ``Y_Hv``, ``Y_Avv``, ``N_Hr``, ``N_Hrrr``; an optional capital
    infix such as ``H`` or ``A``) multiplies an odd function of that velocity and dissipates
    energy only when negative."""
    out = {}
    for name in names:
        match = re.fullmatch(r"([XYZKMN])_?[A-Z]*([a-z]+)", name)
        if match and set(match[2]) == {_OWN_VELOCITY[match[1]]}:
            out[name] = -1.0
    return out


def _verdicts(names: tuple[str, ...], estimate: FloatArray, cov: FloatArray, scale: FloatArray,
              information: FloatArray, max_relative_std: float, damping: Mapping[str, float],
              scale_name: str, weak_floor: float) -> tuple[Any, ...]:
    """Standard deviations, correlations, identifiability, reasons, negative damping and the
    condition number of the scaled information matrix."""
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(std, std)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    null, cond = _null_directions(names, information, weak_floor, 1 / max_relative_std**2)
    if not weak_floor:  # least squares: no prior, so a null direction's std is infinite
        std[[i for i, why in null.items() if why.startswith("collinear")]] = np.inf
    identifiable, reasons = [], []
    for i in range(len(names)):
        rel = std[i] / scale[i]
        partner = _strongest_correlation(names, corr, i)
        if i in null:
            ok, why = False, null[i]
        elif not rel < max_relative_std:
            ok = False
            why = (f"not identifiable: std is {rel:.0%} of the {scale_name} "
                   f"(limit {max_relative_std:.0%})")
            why += partner or "; the data hardly excite it"
        else:
            ok, why = True, f"std {rel:.1%} of the {scale_name}{partner}"
        identifiable.append(ok)
        reasons.append(why)
    negative = np.array([n in damping and estimate[i] != 0
                         and np.sign(estimate[i]) == -np.sign(damping[n])
                         for i, n in enumerate(names)], dtype=bool)
    for i in np.flatnonzero(negative):
        sigmas = abs(estimate[i]) / std[i] if std[i] > 0 else math.inf
        reasons[i] += (f"; NEGATIVE DAMPING: {names[i]} = {estimate[i]:.3g} injects energy "
                       f"(expected {'< 0' if damping[names[i]] < 0 else '> 0'}; {sigmas:.1f} "
                       "std from zero)")
    return std, corr, np.array(identifiable, dtype=bool), tuple(reasons), negative, cond


def _strongest_correlation(names: tuple[str, ...], corr: FloatArray, i: int) -> str:
    others = [j for j in range(len(names)) if j != i]
    if not others:
        return ""
    j = max(others, key=lambda k: abs(corr[i, k]))
    if abs(corr[i, j]) < 0.9:
        return ""
    return f"; correlated with {names[j]} (r = {corr[i, j]:+.3f})"


def _pinv(a: FloatArray) -> FloatArray:
    """Pseudo-inverse of a symmetric matrix, blind to its near null space."""
    return np.linalg.pinv((a + a.T) / 2, rcond=NULL_TOLERANCE, hermitian=True)


def _null_directions(names: tuple[str, ...], information: FloatArray, weak_floor: float,
                     own_floor: float) -> tuple[dict[int, str], float]:
    """Parameters the data do not determine, with a reason each, and the condition number of
    the scaled information matrix ``information`` (parameters in units of their scale).

    A parameter is not excited when, even with every other parameter known, its information is
    below ``own_floor``; it is collinear when it takes part in a weak direction (eigenvalue
    below ``weak_floor`` or numerically zero) together with others.
    """
    lam, vec = np.linalg.eigh((information + information.T) / 2)
    top = max(float(lam[-1]), 0.0)
    cond = top / lam[0] if lam[0] > 0 else math.inf
    out: dict[int, str] = {}
    if top < own_floor:  # the data determine no direction at all
        return {i: "no excitation: the data do not determine it (nor any combination)"
                for i in range(len(names))}, cond
    null = lam < NULL_TOLERANCE * top
    for weak in (null, lam < max(NULL_TOLERANCE * top, weak_floor)):
        for k in np.flatnonzero(weak):
            weights = np.abs(vec[:, k])
            members = [int(i) for i in np.flatnonzero(weights > 0.05 * weights.max())]
            for i in members:
                others = [names[j] for j in members if j != i]
                if i not in out and others:
                    out[i] = (f"collinear with {', '.join(others)}: the data determine only a "
                              f"combination (condition number {cond:.2g})")
        if weak is null:  # exact collinearity first, then lack of excitation
            for i in range(len(names)):
                if i not in out and not information[i, i] >= own_floor:
                    alone = (1 / math.sqrt(information[i, i]) if information[i, i] > 0
                             else math.inf)
                    out[i] = ("no excitation: the data hardly depend on it (even with the "
                              f"others known its std would be {alone:.0%} of its scale)")
    return out, cond


def _result(method: str, names: tuple[str, ...], estimate: FloatArray, cov: FloatArray,
            scale: FloatArray, information: FloatArray, reference: Mapping[str, float] | None,
            max_relative_std: float, damping: Mapping[str, float] | None, scale_name: str,
            weak_floor: float = 0.0, **extra: Any) -> Identification:
    damping = damping_signs(names) if damping is None else dict(damping)
    std, corr, ok, why, negative, cond = _verdicts(names, estimate, cov, scale, information,
                                                   max_relative_std, damping, scale_name,
                                                   weak_floor)
    ref = None if reference is None else np.array(
        [float(reference.get(n, math.nan)) for n in names])
    return Identification(names, estimate, std, corr, ok, why, negative, method, scale, ref,
                          cond, **extra)


def _reference(model_reference: Mapping[str, float] | VehicleModel | None
               ) -> Mapping[str, float] | None:
    if model_reference is None or isinstance(model_reference, Mapping):
        return model_reference
    return {f.name: getattr(model_reference.params, f.name)
            for f in dataclasses.fields(model_reference.params)}


# -- extended Kalman filter ---------------------------------------------------------------------
def identify_ekf(model: VehicleModel, data: Segment | Sequence[Segment],
                 parameters: Sequence[str], *, initial: Mapping[str, float] | None = None,
                 prior_std: Mapping[str, float] | None = None,
                 prior_cov: ArrayLike | None = None,
                 reference: Mapping[str, float] | VehicleModel | None = None,
                 measurement_std: ArrayLike | None = None, process_std: ArrayLike | None = None,
                 state_std: ArrayLike | None = None, substeps: int = 1, smooth: bool = False,
                 damping: Mapping[str, float] | None = None, max_relative_std: float = 0.3
                 ) -> Identification:
    """Joint state and parameter EKF over one or several segments.

    Each segment runs in its own filter of a batch, from the same prior; the parameter
    posteriors are fused: ``P^-1 = sum_i P_i^-1 - (N - 1) P_0^-1`` (exact for linear Gaussian
    models: the prior is counted once). Parameters not listed keep ``model``'s values (use
    ``model.with_params(...)`` to hold them elsewhere).

    :param model: the vehicle model.
    :param data: the segments (all with the same channels and dt).
    :param parameters: names of the parameters to identify.
    :param initial: initial guesses by name (default the model's values), parameter units.
    :param prior_std: prior standard deviation by name (default ``|initial|``): the filter's
        initial uncertainty and the scale of the verdict.
    :param prior_cov: full prior covariance ``(p, p)`` instead of ``prior_std``.
    :param reference: true values (mapping or a model) for ``rel_error``.
    :param measurement_std: noise std per channel ``(m,)`` (default: :func:`noise_std` of the
        first segment).
    :param process_std: process-noise std per model state per period ``(n_x,)`` (default 1 % of
        the measurement std for measured states, 1 % of ``state_std`` for the others).
    :param state_std: initial state std ``(n_x,)`` (default: the measurement std, 1.0 for
        unmeasured states), model units.
    :param substeps: RK4 steps per sample in the filter's prediction.
    :param smooth: also return RTS-smoothed states per segment (``result.states``).
    :param damping: expected signs of damping coefficients (default :func:`damping_signs`).
    :param max_relative_std: identifiable when ``std < max_relative_std * prior std``.
    """
    segments = as_segments(data)
    names = check_parameters(model, parameters)
    _check_data(model, segments)
    theta0 = _values(model, names, initial, "initial")
    if prior_cov is None:
        P_theta = np.diag(_scales(names, theta0, prior_std) ** 2)
    else:
        P_theta = np.array(prior_cov, dtype=float)
        if P_theta.shape != (len(names), len(names)):
            raise ValueError(f"prior_cov has shape {P_theta.shape}; expected "
                             f"({len(names)}, {len(names)})")
    scale = np.sqrt(np.diag(P_theta))
    run = _run_filters(model, segments, names, theta0, P_theta, measurement_std, process_std,
                       state_std, substeps, smooth)
    estimate, cov = run["estimate"], run["cov"]
    unit = np.outer(scale, scale)
    information = _pinv(cov / unit) - _pinv(P_theta / unit)  # what the data added
    result = _result("ekf", names, estimate, cov, scale, information, _reference(reference),
                     max_relative_std, damping, "prior std", weak_floor=1.0,
                     trace_time=run["trace_time"],
                     trace=run["trace"], trace_std=run["trace_std"], states=run["states"],
                     info=run["info"])
    if run["info"]["diverged"]:
        result.identifiable[:] = False
        result.reason = tuple(f"filter diverged on {run['info']['diverged']}; {r}"
                              for r in result.reason)
    return result


def _initial_state(model: VehicleModel, s: Segment) -> FloatArray:
    if s.x0 is not None:
        return s.x0.copy()
    x0 = np.array(model.x0, dtype=float)
    for j, c in enumerate(s.measured):
        if c in model.state_names:
            x0[model.state_names.index(c)] = s.measurements[0, j]
    return x0


def _noise_defaults(model: VehicleModel, s: Segment, measurement_std: ArrayLike | None,
                    process_std: ArrayLike | None, state_std: ArrayLike | None
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Measurement std ``(m,)``, process std ``(n,)`` and initial state std ``(n,)``."""
    n, m = len(model.state_names), len(s.measured)
    r = noise_std(s) if measurement_std is None else np.asarray(measurement_std, dtype=float)
    if r.shape != (m,) or not (np.isfinite(r).all() and (r > 0).all()):
        raise ValueError(f"measurement_std must be {m} values > 0 ({', '.join(s.measured)}); "
                         f"got {r!r}")
    if state_std is None:
        x_std = np.ones(n)
        for j, c in enumerate(s.measured):
            if c in model.state_names:
                x_std[model.state_names.index(c)] = r[j]
    else:
        x_std = np.asarray(state_std, dtype=float)
    q = 0.01 * x_std if process_std is None else np.asarray(process_std, dtype=float)
    for name, a in (("state_std", x_std), ("process_std", q)):
        if a.shape != (n,) or not (np.isfinite(a).all() and (a >= 0).all()):
            raise ValueError(f"{name} must be {n} values >= 0 ({', '.join(model.state_names)})")
    return r, q, x_std


def _run_filters(model: VehicleModel, segments: list[Segment], names: tuple[str, ...],
                 theta0: FloatArray, P_theta: FloatArray, measurement_std: ArrayLike | None,
                 process_std: ArrayLike | None, state_std: ArrayLike | None, substeps: int,
                 smooth: bool) -> dict[str, Any]:
    """The batch of filters (one per segment) and the fusion of their parameter posteriors."""
    first = segments[0]
    r, q, x_std = _noise_defaults(model, first, measurement_std, process_std, state_std)
    n, p, N = len(model.state_names), len(names), len(segments)
    ekf = ExtendedKalmanFilter.from_model(
        model, first.dt, measured=first.measured, Q=q**2, R=r**2, parameters=names,
        angular=first.angular, substeps=substeps, batch_size=N)
    P0 = np.zeros((n + p, n + p))
    P0[:n, :n], P0[n:, n:] = np.diag(x_std**2), P_theta
    x0 = np.array([np.concatenate([_initial_state(model, s), theta0]) for s in segments])
    ekf.reset(x0, P0)
    log = _filter_loop(ekf, segments, smooth)
    ends = np.array([len(s.time) - 1 for s in segments])
    rows = np.arange(N)
    final_theta, final_P = log["theta"][ends, rows], log["P_theta"][ends, rows]
    estimate, cov = _fuse(final_theta, final_P, theta0, P_theta)
    trace, trace_cov = _fuse(log["theta"], log["P_theta"], theta0, P_theta)
    info = {"segments": [s.name for s in segments], "samples": [len(s.time) for s in segments],
            "mean_nis": [float(v) for v in log["mean_nis"]], "channels": list(first.measured),
            "measurement_std": r.tolist(), "diverged": [s.name for s, d in
                                                        zip(segments, ekf.diverged, strict=True)
                                                        if d]}
    return {"estimate": estimate, "cov": cov, "trace": trace,
            "trace_std": np.sqrt(np.maximum(np.diagonal(trace_cov, axis1=-2, axis2=-1), 0.0)),
            "trace_time": np.arange(trace.shape[0]) * first.dt, "info": info,
            "states": _smoothed_states(log, segments, n) if smooth else None}


def _filter_loop(ekf: ExtendedKalmanFilter, segments: list[Segment], keep_all: bool
                 ) -> dict[str, Any]:
    """Step the batch through the segments (ended ones get no more measurements)."""
    N, n = len(segments), len(ekf.model_state_names)
    T = max(len(s.time) for s in segments)
    y, u, d = _padded(segments, T, ekf)
    size = ekf.x.shape[1]
    theta, P_theta = np.empty((T, N, size - n)), np.empty((T, N, size - n, size - n))
    keep = {k: np.empty((T, N, size)) for k in ("x", "x_pred")} if keep_all else {}
    if keep_all:
        keep.update({k: np.empty((T, N, size, size)) for k in ("P", "P_pred")})
        keep["transition"] = np.empty((T - 1, N, size, size))
    nis, dof = np.zeros(N), np.zeros(N)
    for k in range(T):
        if keep_all:
            keep["x_pred"][k], keep["P_pred"][k] = ekf.x, ekf.P
        ekf.update(y[k])
        nis += ekf.nis
        dof += ekf.dof
        theta[k], P_theta[k] = ekf.x[:, n:], ekf.P[:, n:, n:]
        if keep_all:
            keep["x"][k], keep["P"][k] = ekf.x, ekf.P
        if k < T - 1:
            if d is not None:
                ekf.disturbance = d[k]
            ekf.predict(u[k])
            if keep_all:
                keep["transition"][k] = ekf.transition
    mean_nis = nis / np.maximum(dof, 1) * len(ekf.measurement_names)
    return {"theta": theta, "P_theta": P_theta, "mean_nis": mean_nis, **keep}


def _padded(segments: list[Segment], T: int, ekf: ExtendedKalmanFilter
            ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """Measurements ``(T, N, m)`` (NaN after a segment's end), inputs ``(T, N, n_u)`` and
    disturbances (last row held after the end)."""
    N, m = len(segments), len(segments[0].measured)
    y = np.full((T, N, m), np.nan)
    u = np.empty((T, N, segments[0].inputs.shape[1]))
    has_d = any(s.disturbance is not None for s in segments)
    d = np.zeros((T, N, len(ekf.disturbance[0]))) if has_d else None
    for i, s in enumerate(segments):
        L = len(s.time)
        y[:L, i] = s.measurements
        u[:L, i], u[L:, i] = s.inputs, s.inputs[-1]
        if d is not None and s.disturbance is not None:
            dist = np.broadcast_to(s.disturbance, (L, d.shape[2]))
            d[:L, i], d[L:, i] = dist, dist[-1]
    return y, u, d


def _fuse(theta: FloatArray, P: FloatArray, theta0: FloatArray, P0: FloatArray
          ) -> tuple[FloatArray, FloatArray]:
    """Product of ``N`` Gaussian posteriors ``(..., N, p)``, ``(..., N, p, p)`` that share the
    prior ``(theta0, P0)``: the prior is counted once. Returns ``(..., p)``, ``(..., p, p)``.
    Computed in units of the prior std (the coefficients span many decades)."""
    N = theta.shape[-2]
    if N == 1:
        return theta[..., 0, :], P[..., 0, :, :]
    s = np.sqrt(np.diag(P0))
    unit = np.outer(s, s)
    J0 = np.linalg.inv(P0 / unit)
    J_i = np.linalg.inv(P / unit)
    J = J_i.sum(axis=-3) - (N - 1) * J0
    h = (np.einsum("...ij,...j->...i", J_i, theta / s).sum(axis=-2)
         - (N - 1) * J0 @ (theta0 / s))
    # keep J positive definite: linearisation can make the subtraction slightly indefinite
    lam, vec = np.linalg.eigh((J + np.swapaxes(J, -1, -2)) / 2)
    lam = np.maximum(lam, 1e-9 * lam[..., -1:])
    cov = (vec / lam[..., None, :]) @ np.swapaxes(vec, -1, -2)
    mean = np.einsum("...ij,...j->...i", cov, h) * s
    return mean, (cov + np.swapaxes(cov, -1, -2)) / 2 * unit


def _smoothed_states(log: dict[str, Any], segments: list[Segment], n: int) -> list[FloatArray]:
    """Rauch-Tung-Striebel smoothed model states of each segment ``(T_i, n)``."""
    result = FilterResult(x=log["x"], P=log["P"], x_pred=log["x_pred"], P_pred=log["P_pred"],
                          transition=log["transition"], innovation=np.zeros(0),
                          nis=np.zeros(0), dof=np.zeros(0, dtype=np.intp), state_names=())
    smoothed = rts_smooth(result).x
    return [smoothed[:len(s.time), i, :n] for i, s in enumerate(segments)]


# -- staging ------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Stage:
    """One stage of a staged identification.

    :param name: label.
    :param segments: the data of this stage.
    :param parameters: the parameters identified in this stage.
    :param prior: for parameters estimated in an earlier stage: ``"posterior"`` starts from that
        stage's estimate and std (Bayesian chaining; correlations are dropped), ``"initial"``
        from its estimate with the initial prior std (a re-estimation that does not trust the
        earlier std, e.g. when that stage held other parameters at wrong values).
    :param description: why this stage, for reports.
    """

    name: str
    segments: tuple[Segment, ...]
    parameters: tuple[str, ...]
    prior: str = "initial"
    description: str = ""

    def __post_init__(self) -> None:
        if self.prior not in ("posterior", "initial"):
            raise ValueError(f"prior={self.prior!r} is invalid: 'posterior' or 'initial'")
        object.__setattr__(self, "segments", tuple(as_segments(self.segments)))
        object.__setattr__(self, "parameters", tuple(self.parameters))


def identify_staged(model: VehicleModel, stages: Sequence[Stage], *,
                    initial: Mapping[str, float] | None = None,
                    prior_std: Mapping[str, float] | None = None,
                    **kwargs: Any) -> list[Identification]:
    """Stages of :func:`identify_ekf`, each using the previous stages' estimates.

    In stage ``j`` the parameters of earlier stages that are not identified again are held at
    their latest estimates, those not yet identified at ``initial``; parameters identified again
    start from their latest estimate (see :attr:`Stage.prior`).

    :param initial: initial guesses of every staged parameter (default the model's values).
    :param prior_std: initial prior std by name (default ``|initial|``).
    :param kwargs: passed to :func:`identify_ekf` (``reference``, ``measurement_std``, ...).
    """
    stages = list(stages)
    if not stages:
        raise ValueError("no stages given")
    every = tuple(dict.fromkeys(n for s in stages for n in s.parameters))
    check_parameters(model, every)
    current = dict(zip(every, _values(model, every, initial, "initial"), strict=True))
    std0 = dict(zip(every, _scales(every, np.array(list(current.values())), prior_std),
                    strict=True))
    posterior: dict[str, tuple[float, float]] = {}
    results = []
    for stage in stages:
        held = {k: v for k, v in current.items() if k not in stage.parameters}
        staged_model = model.with_params(**held) if held else model
        start = {k: current[k] for k in stage.parameters}
        std = {k: (posterior[k][1] if stage.prior == "posterior" and k in posterior
                   else std0[k]) for k in stage.parameters}
        result = identify_ekf(staged_model, list(stage.segments), stage.parameters,
                              initial=start, prior_std=std, **kwargs)
        result.info.update(stage=stage.name, held={k: float(v) for k, v in held.items()},
                           description=stage.description)
        results.append(result)
        for k, v, s in zip(result.names, result.estimate, result.std, strict=True):
            current[k] = float(v)
            posterior[k] = (float(v), float(s))
    return results


# -- least squares ------------------------------------------------------------------------------
def identify_least_squares(model: VehicleModel, data: Segment | Sequence[Segment],
                           parameters: Sequence[str], *, method: str = "equation_error",
                           initial: Mapping[str, float] | None = None,
                           scale: Mapping[str, float] | None = None,
                           reference: Mapping[str, float] | VehicleModel | None = None,
                           measurement_std: ArrayLike | None = None, window: float = 2.0,
                           substeps: int = 1, max_iterations: int = 20,
                           damping: Mapping[str, float] | None = None,
                           max_relative_std: float = 0.3) -> Identification:
    """Batch least-squares identification: equation error or output error (module docstring).

    :param model: the vehicle model; parameters not listed keep its values.
    :param data: the segments.
    :param parameters: names of the parameters to identify.
    :param method: ``"equation_error"`` or ``"output_error"``.
    :param initial: starting values by name (default the model's values). Equation error on
        parameters in which ``rhs`` is affine does not depend on them.
    :param scale: typical magnitude by name (default ``|initial|``): conditions the problem and
        sets the verdict's scale.
    :param reference: true values (mapping or model) for ``rel_error``.
    :param measurement_std: noise std per channel (default :func:`noise_std`).
    :param window: Savitzky-Golay window (equation error), s.
    :param substeps: RK4 steps per sample (output error).
    :param max_iterations: Gauss-Newton iterations (equation error, non-affine parameters) or
        simulations (output error; each gives the residuals and their Jacobian).
    :param damping: expected signs of damping coefficients (default :func:`damping_signs`).
    :param max_relative_std: identifiable when ``std < max_relative_std * scale``.
    """
    segments = as_segments(data)
    names = check_parameters(model, parameters)
    _check_data(model, segments)
    theta0 = _values(model, names, initial, "initial")
    s = _scales(names, theta0, scale, "scale")
    r = noise_std(segments[0]) if measurement_std is None else np.asarray(measurement_std,
                                                                          dtype=float)
    if r.shape != (len(segments[0].measured),) or not (r > 0).all():
        raise ValueError(f"measurement_std must be {len(segments[0].measured)} values > 0")
    if method == "equation_error":
        fit = _equation_error(model, segments, names, theta0, s, window, max_iterations)
    elif method == "output_error":
        fit = _output_error(model, segments, names, theta0, s, r, substeps, max_iterations)
    else:
        raise ValueError(f"method={method!r} is invalid: 'equation_error' or 'output_error'")
    return _result(method, names, fit["estimate"], fit["cov"], s, fit["information"],
                   _reference(reference), max_relative_std, damping,
                   "scale" if scale else "initial magnitude", info=fit["info"])


def _window_samples(window: float, dt: float, segments: list[Segment]) -> int:
    w = int(round(window / dt)) | 1  # odd
    w = max(w, 7)
    shortest = min(len(s.time) for s in segments)
    if shortest < 2 * w + 1:
        raise ValueError(f"segment too short for the equation-error fit: {shortest} samples, "
                         f"need at least {2 * w + 1} (smoothing window {w} samples = "
                         f"{w * dt:g} s; shorten window=)")
    return w


def _regression_data(model: VehicleModel, segments: list[Segment], w: int
                     ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, list[int],
                                FloatArray]:
    """Smoothed states, their derivatives, inputs, disturbances (valid samples of all segments
    stacked) and the state indices of the measured states; plus each sample's segment id."""
    state_rows = [model.state_names.index(c) if c in model.state_names else -1
                  for c in segments[0].measured]
    if -1 in state_rows:
        raise ValueError(f"equation error needs measured states; {segments[0].measured} "
                         f"includes outputs that are not states of model {model.name!r}")
    _check_measured_inputs(model, segments[0], state_rows)
    xs, xds, us, ds, ids = [], [], [], [], []
    for i, seg in enumerate(segments):
        y = seg.unwrapped()
        ys = scipy.signal.savgol_filter(y, w, 3, axis=0)
        yd = scipy.signal.savgol_filter(y, w, 3, deriv=1, delta=seg.dt, axis=0)
        valid = _valid_samples(seg, w)
        x = np.tile(_initial_state(model, seg), (len(seg.time), 1))
        x[:, state_rows] = ys
        xs.append(x[valid])
        xds.append(yd[valid])
        us.append(seg.inputs[valid])
        dist = np.zeros((len(seg.time), len(model.disturbance_names))) \
            if seg.disturbance is None else np.broadcast_to(
                seg.disturbance, (len(seg.time), len(model.disturbance_names)))
        ds.append(dist[valid])
        ids.append(np.full(int(valid.sum()), i))
    return (np.concatenate(xs), np.concatenate(xds), np.concatenate(us), np.concatenate(ds),
            state_rows, np.concatenate(ids))


def _check_measured_inputs(model: VehicleModel, seg: Segment, rows: list[int]) -> None:
    """The derivatives of the measured states must not depend on unmeasured states (equation
    error has no value for them); checked on the linearisation at the first sample."""
    x = _initial_state(model, seg)
    A, _, _ = model.linearize(x, seg.inputs[0])
    hidden = [j for j in range(len(x)) if j not in rows]
    used = [model.state_names[j] for j in hidden if np.any(A[rows, j] != 0)]
    if used:
        raise ValueError(f"equation error needs every state the fitted equations use; "
                         f"{', '.join(used)} are not measured (use method='output_error' or "
                         "identify_ekf)")


def _valid_samples(seg: Segment, w: int) -> NDArray[np.bool_]:
    """Samples away from the ends and from input steps (where the derivative jumps and the
    smoother would blur it)."""
    T, half = len(seg.time), w // 2
    valid = np.zeros(T, dtype=bool)
    valid[half:T - half] = True
    steps = np.flatnonzero(np.any(np.diff(seg.inputs, axis=0) != 0, axis=1)) + 1
    for k in steps:
        valid[max(0, k - half):k + half] = False
    if valid.sum() < MIN_SAMPLES:
        raise ValueError(f"{seg.label}: only {int(valid.sum())} samples away from the ends and "
                         "the input steps; the equation-error fit needs a longer or smoother run")
    return valid


def _parameter_jacobian(model: VehicleModel, x: FloatArray, u: FloatArray, d: FloatArray,
                        names: tuple[str, ...], theta: FloatArray, s: FloatArray
                        ) -> tuple[FloatArray, FloatArray]:
    """``rhs_with`` at ``theta`` ``(K, n)`` and its derivative ``(K, n, p)``."""
    values = dict(zip(names, theta, strict=True))
    f = model.rhs_with(x, u, d, values)
    G = model.parameter_jacobian(x, u, d, values)
    if G is None:  # central differences, step 1e-6 of each scale
        cols = []
        for j, n in enumerate(names):
            h = 1e-6 * s[j]
            plus = model.rhs_with(x, u, d, {**values, n: theta[j] + h})
            minus = model.rhs_with(x, u, d, {**values, n: theta[j] - h})
            cols.append((plus - minus) / (2 * h))
        G = np.stack(cols, axis=-1)
    return f, G


def _equation_error(model: VehicleModel, segments: list[Segment], names: tuple[str, ...],
                    theta0: FloatArray, s: FloatArray, window: float, max_iterations: int
                    ) -> dict[str, Any]:
    """Weighted (per equation) least squares of the derivatives on ``d rhs / d theta``,
    Gauss-Newton; covariance with a Newey-West correction for the smoother's correlation."""
    w = _window_samples(window, segments[0].dt, segments)
    x, xd, u, d, rows, ids = _regression_data(model, segments, w)
    affine = set(names) <= model.affine_parameters
    theta, iterations = theta0.copy(), 0
    while iterations < max_iterations:
        iterations += 1
        f, G = _parameter_jacobian(model, x, u, d, names, theta, s)
        A = G[:, rows, :] * s  # scaled regressors (K, m, p)
        b = xd - f[:, rows]
        used = np.abs(A).max(axis=(0, 2)) > 0  # equations the parameters appear in
        step, cov, info_matrix, sigma = _weighted_fit(A[:, used], b[:, used], ids, w)
        theta = theta + s * step
        if affine or np.max(np.abs(step)) < 1e-9:
            break
    equations = [model.state_names[r] + "_dot" for r, k in zip(rows, used, strict=True) if k]
    info = {"iterations": iterations, "window_s": w * segments[0].dt, "samples": int(len(x)),
            "equations": equations, "residual_std": dict(zip(equations, sigma.tolist(),
                                                             strict=True))}
    return {"estimate": theta, "cov": cov * np.outer(s, s), "information": info_matrix,
            "info": info}


def _weighted_fit(A: FloatArray, b: FloatArray, ids: FloatArray, w: int
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Two-step weighted least squares of ``b (K, m) = A (K, m, p) z``: ordinary, then weighted
    by each equation's residual variance. Returns ``z``, its Newey-West covariance, the weighted
    information matrix and the residual std per equation."""
    K, m, p = A.shape
    X, Y = A.reshape(K * m, p), b.reshape(K * m)
    z = np.linalg.lstsq(X, Y, rcond=None)[0]
    sigma = np.sqrt(np.mean((b - A @ z) ** 2, axis=0))
    sigma = np.where(sigma > 0, sigma, 1.0)
    Aw, bw = A / sigma[None, :, None], b / sigma
    X, Y = Aw.reshape(K * m, p), bw.reshape(K * m)
    information = X.T @ X
    bread = _pinv(information)
    z = bread @ (X.T @ Y)
    score = np.einsum("kmp,km->kp", Aw, bw - Aw @ z)  # per-sample gradient contributions
    meat = _newey_west(score, ids, w)
    cov = bread @ meat @ bread
    return z, (cov + cov.T) / 2, information, sigma


def _newey_west(score: FloatArray, ids: FloatArray, lags: int) -> FloatArray:
    """Sum of the scores' autocovariances up to ``lags`` (Bartlett weights), within segments."""
    meat = score.T @ score
    for lag in range(1, lags + 1):
        same = ids[lag:] == ids[:-lag]
        g = score[lag:][same].T @ score[:-lag][same]
        meat += (1 - lag / (lags + 1)) * (g + g.T)
    return meat


def _output_error(model: VehicleModel, segments: list[Segment], names: tuple[str, ...],
                  theta0: FloatArray, s: FloatArray, r: FloatArray, substeps: int,
                  max_iterations: int) -> dict[str, Any]:
    """Fit simulated outputs to the measurements; the measured initial states are fitted too."""
    sim = _Simulation(model, segments, names, theta0, s, r, substeps)
    z0 = np.zeros(sim.size)
    fit = scipy.optimize.least_squares(sim.residuals, z0, jac=sim.jacobian, method="trf",
                                       x_scale=1.0, max_nfev=max_iterations)
    J = fit.jac
    dof = max(J.shape[0] - J.shape[1], 1)
    s2 = 2 * fit.cost / dof  # ~1 when measurement_std is right
    information_all = J.T @ J
    cov_all = _pinv(information_all) * s2
    p = len(names)
    cov = cov_all[:p, :p] * np.outer(s, s)
    # the parameters' information with the initial states profiled out (Schur complement)
    Ipp, Ipx, Ixx = information_all[:p, :p], information_all[:p, p:], information_all[p:, p:]
    information = Ipp - Ipx @ _pinv(Ixx) @ Ipx.T if Ixx.size else Ipp
    info = {"evaluations": int(fit.nfev), "status": int(fit.status),
            "residual_rms": float(math.sqrt(s2)), "samples": int(J.shape[0])}
    return {"estimate": theta0 + s * fit.x[:p], "cov": cov, "information": information,
            "info": info}


class _Simulation:
    """Batched RK4 simulation of every segment for the parameter vector and its forward
    perturbations, so that residuals and their Jacobian come from one pass over time."""

    def __init__(self, model: VehicleModel, segments: list[Segment], names: tuple[str, ...],
                 theta0: FloatArray, s: FloatArray, r: FloatArray, substeps: int) -> None:
        self.model, self.segments, self.names = model, segments, names
        self.theta0, self.s, self.r, self.substeps = theta0, s, r, substeps
        first = segments[0]
        self.rows = [model.state_names.index(c) if c in model.state_names else -1
                     for c in first.measured]
        self.x_rows = [j for j, k in enumerate(self.rows) if k >= 0]  # measured states
        self.x0 = [_initial_state(model, seg) for seg in segments]
        self.p, self.N = len(names), len(segments)
        self.size = self.p + self.N * len(self.x_rows)
        self.angular = [first.measured.index(c) for c in first.angular]
        self.T = max(len(seg.time) for seg in segments)
        self.y, self.u, self.d = self._stack()
        self._cache: tuple[FloatArray, FloatArray, FloatArray] | None = None

    def _stack(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        T, n_d = self.T, len(self.model.disturbance_names)
        y = np.full((T, self.N, len(self.r)), np.nan)
        u = np.empty((T, self.N, self.segments[0].inputs.shape[1]))
        d = np.zeros((T, self.N, n_d))
        for i, seg in enumerate(self.segments):
            L = len(seg.time)
            y[:L, i] = seg.unwrapped()
            u[:L, i], u[L:, i] = seg.inputs, seg.inputs[-1]
            if seg.disturbance is not None:
                dist = np.broadcast_to(seg.disturbance, (L, n_d))
                d[:L, i], d[L:, i] = dist, dist[-1]
        return y, u, d

    def _variants(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Parameters ``(V, p)`` and initial states ``(V, N, n)`` of the nominal and each
        perturbed variant (forward differences, step 1e-6 ... of the scaled variable)."""
        V = self.size + 1
        h = 1e-6 * np.maximum(1.0, np.abs(z))
        Z = np.tile(z, (V, 1))
        Z[np.arange(1, V), np.arange(self.size)] += h
        theta = self.theta0 + self.s * Z[:, :self.p]
        x0 = np.tile(np.array(self.x0), (V, 1, 1))
        offsets = Z[:, self.p:].reshape(V, self.N, len(self.x_rows))
        for j, c in enumerate(self.x_rows):
            x0[:, :, self.rows[c]] += self.r[c] * offsets[:, :, j]
        return theta, x0, h

    def _simulate(self, theta: FloatArray, x0: FloatArray) -> FloatArray:
        """Outputs ``(T, V, N, m)`` of the variants."""
        V, N = theta.shape[0], self.N
        x = x0.reshape(V * N, -1)
        params = {n: np.repeat(theta[:, j], N) for j, n in enumerate(self.names)}
        dt, out = self.segments[0].dt / self.substeps, np.empty((self.T, V * N, len(self.r)))
        channels = [self.model.output_names.index(c) for c in self.segments[0].measured]

        def f(state: FloatArray, u: FloatArray, d: FloatArray) -> FloatArray:
            return self.model.rhs_with(state, u, d, params)

        for k in range(self.T):
            out[k] = self.model.output(x)[:, channels]
            if k == self.T - 1:
                break
            u, d = np.tile(self.u[k], (V, 1)), np.tile(self.d[k], (V, 1))
            for _ in range(self.substeps):
                k1 = f(x, u, d)
                k2 = f(x + 0.5 * dt * k1, u, d)
                k3 = f(x + 0.5 * dt * k2, u, d)
                k4 = f(x + dt * k3, u, d)
                x = x + dt / 6 * (k1 + 2 * (k2 + k3) + k4)
        return out.reshape(self.T, V, N, -1)

    def _evaluate(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self._cache is not None and np.array_equal(self._cache[0], z):
            return self._cache[1], self._cache[2]
        theta, x0, h = self._variants(z)
        out = self._simulate(theta, x0)
        e = out - self.y[:, None]
        if self.angular:
            e[..., self.angular] = (e[..., self.angular] + np.pi) % (2 * np.pi) - np.pi
        e = e / self.r
        valid = np.isfinite(self.y)  # (T, N, m)
        res = np.where(valid[:, None], e, 0.0).reshape(self.T, len(theta), -1)
        res = np.moveaxis(res, 1, 0).reshape(len(theta), -1)
        jac = ((res[1:] - res[0]) / h[:, None]).T
        self._cache = (z.copy(), res[0], jac)
        return res[0], jac

    def residuals(self, z: FloatArray) -> FloatArray:
        return self._evaluate(z)[0]

    def jacobian(self, z: FloatArray) -> FloatArray:
        return self._evaluate(z)[1]


__all__ = ["Identification", "Segment", "Stage", "as_segments", "check_parameters",
           "damping_signs", "identify_ekf", "identify_least_squares", "identify_staged",
           "noise_std"]
