"""Batch least-squares identification, :func:`identify_least_squares`, and its equation-error
fit.

* ``method="equation_error"``: the accelerations (Savitzky-Golay derivatives of the
  measurements) regressed on ``d rhs / d theta``; exact in one step for parameters in which
  ``rhs`` is affine, Gauss-Newton otherwise. Needs no initial guess of the parameters, but every
  state the fitted equations use must be measured.
* ``method="output_error"`` (:mod:`estimators.identification.output_error`): simulated outputs
  fitted to the measured ones (``scipy.optimize.least_squares``), initial states included. The
  maximum-likelihood fit when the only noise is the sensors', but one simulation of every
  segment per parameter and iteration.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.signal
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel

from .data import (
    MIN_SAMPLES,
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
from .output_error import _output_error
from .result import Identification, _pinv, _reference, _result


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
