"""Joint state and parameter identification with an extended Kalman filter, the hovercraft EKF
paper's method: :func:`identify_ekf`.

The parameters are appended to the state of an :class:`~estimators.ekf.ExtendedKalmanFilter`.
Several segments run as a batch of filters from the same prior and their parameter posteriors are
fused (product of the Gaussian likelihoods, :func:`_fuse`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from marine_envs.models import VehicleModel

from ..ekf import ExtendedKalmanFilter, FilterResult, rts_smooth
from .data import (
    FloatArray,
    Segment,
    _check_data,
    _initial_state,
    _scales,
    _values,
    as_segments,
    check_parameters,
    noise_std,
)
from .result import Identification, _pinv, _reference, _result


def identify_ekf(model: VehicleModel, data: Segment | Sequence[Segment],
                 parameters: Sequence[str], *, initial: Mapping[str, float] | None = None,
                 prior_std: Mapping[str, float] | None = None,
                 prior_cov: ArrayLike | None = None,
                 reference: Mapping[str, float] | VehicleModel | None = None,
                 measurement_std: ArrayLike | None = None, process_std: ArrayLike | None = None,
                 state_std: ArrayLike | None = None, substeps: int = 1, smooth: bool = False,
                 damping: Mapping[str, float] | None = None, max_relative_std: float = 0.3,
                 compiled: bool = True) -> Identification:
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
    :param compiled: the filter's compiled path where the model has one (as
        :meth:`ExtendedKalmanFilter.from_model`); False: the numpy path.
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
                       state_std, substeps, smooth, compiled)
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
                 smooth: bool, compiled: bool = True) -> dict[str, Any]:
    """The batch of filters (one per segment) and the fusion of their parameter posteriors."""
    first = segments[0]
    r, q, x_std = _noise_defaults(model, first, measurement_std, process_std, state_std)
    n, p, N = len(model.state_names), len(names), len(segments)
    ekf = ExtendedKalmanFilter.from_model(
        model, first.dt, measured=first.measured, Q=q**2, R=r**2, parameters=names,
        angular=first.angular, substeps=substeps, batch_size=N, compiled=compiled)
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
                                                        if d], "compiled": ekf.compiled}
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
