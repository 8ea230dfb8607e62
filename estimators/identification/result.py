"""The result of an identification, :class:`Identification`, and its verdicts.

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
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from marine_envs.models import VehicleModel

from .data import FloatArray

#: A direction of the scaled information matrix with an eigenvalue below this fraction of the
#: largest is taken as not excited (numerically rank deficient).
NULL_TOLERANCE = 1e-10
#: Force/moment letter -> its own velocity (SNAME): X_u, Y_v, Z_w, K_p, M_q, N_r are damping.
_OWN_VELOCITY = {"X": "u", "Y": "v", "Z": "w", "K": "p", "M": "q", "N": "r"}


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
    # below rounding level an eigenvalue is zero, whatever sign LAPACK happens to give it
    cond = top / lam[0] if lam[0] > len(lam) * np.finfo(float).eps * top else math.inf
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
