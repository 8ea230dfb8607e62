"""Step 2: every catalogue entry as a hypothesis about the equation errors, fitted by least squares.

Each hypothesis predicts a *contribution* ``C(theta)`` ``(T - 1, n)`` to the equation errors
``e`` (state units per second): the term it adds, evaluated on the smoothed states. Terms linear in
their coefficient (a current, a damping, a coupling, a sensor bias, an input gain) are solved in
closed form; the others (a delay, a limit, a dead zone, a rate, a change time) on a grid of their
one nonlinear parameter, with the coefficient concentrated out. Every fit uses the first part of
the record only (``fit``), weighted per state equation by the inverse variance of its errors, so
one number compares hypotheses that act on different equations.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal, stats

from marine_envs.effects import Effect, applied_inputs

from .residuals import Residuals, _output_matrix

FloatArray = NDArray[np.float64]


@dataclass
class Fitted:
    """A fitted hypothesis: the effect with its parameters, their standard deviations and its
    contribution to the equation errors over the whole record."""

    effect: Effect
    contribution: FloatArray
    std: dict[str, float] = field(default_factory=dict)
    n_parameters: int = 1
    multiplicity: int = 1  # how many tries the search made for this one (a grid, a library)
    details: dict[str, Any] = field(default_factory=dict)


@dataclass
class Problem:
    """What every hypothesis is fitted to: the residuals, the current equation errors (minus the
    findings already accepted), the fit rows and the per-equation weights."""

    residuals: Residuals
    error: FloatArray
    fit: NDArray[np.bool_]
    weights: FloatArray
    inflation: FloatArray  # per equation, sqrt of the variance inflation of autocorrelation

    @classmethod
    def build(cls, residuals: Residuals, error: FloatArray, fit_fraction: float) -> Problem:
        fit = np.arange(len(error)) < int(fit_fraction * len(error))
        variance = np.var(error[fit], axis=0)
        # unmeasured states follow the model (see residuals.FOLLOW_MODEL): their errors are ~0
        measured = np.array([n in residuals.channels for n in residuals.model.state_names])
        usable = residuals.observable & measured & (variance > 0)
        weights = np.where(usable, 1 / np.where(variance > 0, variance, 1.0), 0.0)
        e = error[fit]
        rho = np.clip(np.sum(e[1:] * e[:-1], axis=0) / np.maximum(np.sum(e * e, axis=0), 1e-300),
                      0.0, 0.98)
        return cls(residuals, error, fit, weights, np.sqrt((1 + rho) / (1 - rho)))

    @property
    def model(self):
        return self.residuals.model

    def sse(self, contribution: FloatArray, rows: NDArray[np.bool_] | None = None) -> float:
        rows = self.fit if rows is None else rows
        r = self.error[rows] - contribution[rows]
        return float(np.sum(r * r * self.weights))


# -- the hypotheses ------------------------------------------------------------------------------
def all_hypotheses(problem: Problem) -> Iterator[Fitted]:
    """Every hypothesis the catalogue allows for this model and these channels, fitted."""
    yield from state_terms(problem)
    yield from parameter_changes(problem)
    yield from input_effects(problem)
    yield from sensor_biases(problem)
    yield from wave_frequencies(problem)
    yield from unlisted_terms(problem)


def _targets(problem: Problem) -> list[int]:
    return [i for i in range(len(problem.model.state_names)) if problem.weights[i] > 0]


def _single_row(problem: Problem, effect: str, i: int, regressor: FloatArray,
                parameters: dict[str, Any], name: str = "c") -> Fitted | None:
    """Fit ``c * regressor`` in equation ``i``."""
    fit = problem.fit
    phi, e = regressor[fit], problem.error[fit, i]
    den = float(phi @ phi)
    if den <= 1e-300 * len(phi) or np.ptp(regressor) == 0 and effect != "current":
        return None
    c = float(phi @ e) / den
    sigma = np.sqrt(np.mean((e - c * phi) ** 2)) * problem.inflation[i]
    contribution = np.zeros_like(problem.error)
    contribution[:, i] = c * regressor
    target = problem.model.state_names[i]
    return Fitted(Effect(effect, target, {**parameters, name: c}), contribution,
                  {name: float(sigma / np.sqrt(den))})


def state_terms(problem: Problem) -> Iterator[Fitted]:
    """Current, linear/quadratic/cubic damping, coupling and cubic restoring terms."""
    x, names = problem.residuals.midpoint, problem.model.state_names
    for i in _targets(problem):
        xi = x[:, i]
        terms = [("current", np.ones_like(xi), {}),
                 ("linear_damping", xi, {}),
                 ("quadratic_damping", xi * np.abs(xi), {}),
                 ("nonlinear_damping", xi**3, {"form": "cubic"})]
        for s, source in enumerate(names):
            if s != i and problem.residuals.observable[s]:
                terms.append(("coupling", x[:, s], {"source": source}))
                terms.append(("nonlinear_restoring", x[:, s] ** 3, {"source": source}))
        for effect, regressor, fixed in terms:
            fitted = _single_row(problem, effect, i, regressor, fixed,
                                 "b" if effect == "current" else "c")
            if fitted is not None:
                yield fitted


def parameter_changes(problem: Problem, margin: float = 0.05) -> Iterator[Fitted]:
    """A step change at an unknown time of the damping (``c * x_t``) or of a constant force in
    one equation: every change time on the fit rows by cumulative sums."""
    x, time = problem.residuals.midpoint, problem.residuals.time[:-1]
    n_fit = int(problem.fit.sum())
    lo, hi = int(margin * len(time)), n_fit - int(margin * len(time))
    if hi <= lo + 2:
        return
    for i in _targets(problem):
        e = problem.error[:n_fit, i]
        for what, regressor in (("damping", x[:, i]), ("force", np.ones(len(x)))):
            phi = regressor[:n_fit]
            num = np.cumsum((phi * e)[::-1])[::-1]
            den = np.cumsum((phi * phi)[::-1])[::-1]
            gain = np.where(den > 0, num**2 / np.maximum(den, 1e-300), 0.0)
            k = lo + int(np.argmax(gain[lo:hi]))
            step = (np.arange(len(x)) >= k).astype(float)
            fitted = _single_row(problem, "parameter_change", i, step * regressor,
                                 {"time": float(time[k]), "what": what})
            if fitted is None:
                continue
            fitted.std["time"] = _change_time_std(gain, k, problem.residuals.dt)
            fitted.n_parameters, fitted.multiplicity = 2, 10
            yield fitted


def _change_time_std(gain: FloatArray, k: int, dt: float) -> float:
    """Half the width (s) over which the explained sum of squares stays within one unit of
    chi-square of its best (a likelihood interval for the change time)."""
    if gain[k] <= 0:
        return float("inf")
    within = np.flatnonzero(gain >= gain[k] * (1 - 1 / max(gain[k], 1.0)))
    return float((within.max() - within.min() + 1) * dt / 2)


def input_effects(problem: Problem) -> Iterator[Fitted]:
    """Gain (closed form), delay, saturation, dead zone and rate limit (grids) of each input."""
    res = problem.residuals
    model, u, dt = problem.model, res.u, res.dt
    x = res.midpoint
    base = model.rhs(x, u[:-1])

    def contribution(effect: Effect) -> FloatArray:
        return model.rhs(x, applied_inputs(effect, model, u, dt)[:-1]) - base

    for j, name in enumerate(model.input_names):
        c = u[:, j] - model.u0[j]
        spread = float(np.std(c))
        if spread <= 0:
            continue
        unit = contribution(Effect("input_gain", name, {"k": 2.0}))
        fitted = _scaled(problem, unit, Effect("input_gain", name, {"k": 1.0}), "k", offset=1.0)
        if fitted is not None:
            yield fitted
        magnitude = np.abs(c)
        rates = np.abs(np.diff(c)) / dt
        grids = {
            "input_delay": ("tau", dt * np.arange(1, max(2, int(3.0 / dt)) + 1)),
            "input_saturation": ("limit", np.quantile(magnitude, np.linspace(0.5, 0.995, 25))),
            "input_deadzone": ("width", np.quantile(magnitude, np.linspace(0.02, 0.6, 25))),
            "input_rate_limit": ("rate", np.quantile(rates[rates > 0], np.linspace(0.5, 0.995, 25))
                                 if np.any(rates > 0) else np.array([])),
        }
        for effect, (parameter, grid) in grids.items():
            grid = np.unique(grid[grid > 0])
            if grid.size:
                fitted = _grid(problem, [Effect(effect, name, {parameter: float(g)})
                                         for g in grid], contribution, parameter)
                if fitted is not None:
                    yield fitted


def _scaled(problem: Problem, unit: FloatArray, effect: Effect, name: str,
            offset: float = 0.0) -> Fitted | None:
    """Fit ``a * unit`` over every equation; the parameter is ``offset + a``."""
    w, fit = problem.weights, problem.fit
    den = float(np.sum(unit[fit] ** 2 * w))
    if den <= 0:
        return None
    a = float(np.sum(unit[fit] * problem.error[fit] * w)) / den
    inflation = float(np.max(problem.inflation[w > 0])) if np.any(w > 0) else 1.0
    parameters = {**effect.parameters, name: offset + a}
    sigma = np.sqrt(max(problem.sse(a * unit), 0.0) / max(int(fit.sum()) * int((w > 0).sum()), 1))
    return Fitted(Effect(effect.effect, effect.target, parameters), a * unit,
                  {name: float(inflation * sigma / np.sqrt(den))})


def _grid(problem: Problem, effects: list[Effect], contribution, parameter: str) -> Fitted | None:
    """The best of a grid of one-parameter effects, its std from the curvature of the SSE."""
    contributions = [contribution(e) for e in effects]
    sse = np.array([problem.sse(c) for c in contributions])
    k = int(np.argmin(sse))
    values = np.array([e.parameters[parameter] for e in effects])
    std = _curvature_std(values, sse, k, problem)
    return Fitted(effects[k], contributions[k], {parameter: std}, multiplicity=len(effects))


def _curvature_std(values: FloatArray, sse: FloatArray, k: int, problem: Problem) -> float:
    """Standard deviation of a grid parameter from a parabola through the SSE around its
    minimum (SSE in units of the weighted residual variance, inflated for autocorrelation)."""
    if k == 0 or k == len(values) - 1:
        return float(abs(values[-1] - values[0]))
    a, _, _ = np.polyfit(values[k - 1:k + 2], sse[k - 1:k + 2], 2)
    n = int(problem.fit.sum()) * max(int((problem.weights > 0).sum()), 1)
    scale = sse[k] / n * float(np.max(problem.inflation)) ** 2
    return float(np.sqrt(scale / a)) if a > 0 else float(abs(values[-1] - values[0]))


def sensor_biases(problem: Problem) -> Iterator[Fitted]:
    """A constant offset on a measured channel: the smoothed state is shifted by it, so the
    equations see ``f(x - b dx/dy) - f(x)``."""
    res = problem.residuals
    model, x, u = problem.model, res.midpoint, res.u[:-1]
    C = _output_matrix(model, res.channels)
    base = model.rhs(x, u)
    for j, channel in enumerate(res.channels):
        direction = np.linalg.pinv(C)[:, j]
        if not np.any(direction):
            continue
        step = 0.1 * float(np.std(res.y[:, j])) + 1e-12
        unit = (model.rhs(x - step * direction, u) - base) / step
        if np.sum(unit[problem.fit] ** 2 * problem.weights) <= 1e-12 * np.sum(problem.weights):
            continue  # a channel nothing depends on (a heading): a bias there is invisible
        fitted = _scaled(problem, unit, Effect("sensor_bias", channel, {"b": 0.0}), "b")
        if fitted is not None:
            yield fitted


def wave_frequencies(problem: Problem, alpha: float = 1e-3,
                     max_zeta: float = 0.25) -> Iterator[Fitted]:
    """A narrow-band process in one equation: a significant, narrow (``zeta <= max_zeta``) peak
    of its error spectrum over a smooth background; the contribution is the band's excess,
    band-pass filtered."""
    dt = problem.residuals.dt
    for i in _targets(problem):
        peak = spectral_peak(problem.error[problem.fit, i], dt)
        if peak is None or peak["p_value"] > alpha or peak["zeta"] > max_zeta:
            continue
        omega, zeta = peak["omega"], peak["zeta"]
        band = _band_pass(problem.error[:, i], omega, max(zeta, peak["resolution"]), dt)
        contribution = np.zeros_like(problem.error)
        contribution[:, i] = band * (1 - 1 / peak["ratio"])
        target = problem.model.state_names[i]
        yield Fitted(Effect("wave_frequency", target, {"omega": omega, "zeta": zeta}),
                     contribution, {"omega": peak["resolution"] / 2, "zeta": zeta / 2},
                     n_parameters=2, multiplicity=1, details=peak)


def spectral_peak(x: FloatArray, dt: float, segment: float = 60.0) -> dict[str, float] | None:
    """The most significant peak of the Welch spectrum of ``x`` over a running-median background:
    ``omega`` (rad/s), ``zeta`` (from the half-power width), ``ratio`` (peak/background),
    ``p_value`` (chi-square, Bonferroni over the frequencies), ``resolution`` (rad/s)."""
    nperseg = min(len(x) // 4, int(segment / dt))
    if nperseg < 32:
        return None
    f, psd = signal.welch(x, fs=1 / dt, nperseg=nperseg)
    omega = 2 * np.pi * f
    usable = (omega > 0.15) & (omega < 0.8 * np.pi / dt)
    if usable.sum() < 10:
        return None
    background = np.exp(signal.medfilt(np.log(psd + 1e-300), 2 * (len(psd) // 16) + 1))
    ratio = np.where(usable, psd / background, 0.0)
    k = int(np.argmax(ratio))
    dof = 2 * 1.8 * (2 * len(x) / nperseg - 1)  # Hann, half overlap
    p_value = min(1.0, float(stats.chi2.sf(ratio[k] * dof, dof)) * int(usable.sum()))
    half = psd[k] / 2
    lo, hi = k, k
    while lo > 0 and psd[lo] > half:
        lo -= 1
    while hi < len(psd) - 1 and psd[hi] > half:
        hi += 1
    resolution = 2 * np.pi / (nperseg * dt)
    peak = _parabolic(omega, np.log(psd + 1e-300), k)
    width = max(omega[hi] - omega[lo] - resolution, resolution / 2)
    return {"omega": float(peak), "zeta": float(width / (2 * peak)), "ratio": float(ratio[k]),
            "p_value": p_value, "resolution": float(resolution)}


def _parabolic(x: FloatArray, y: FloatArray, k: int) -> float:
    if k == 0 or k == len(x) - 1:
        return float(x[k])
    a, b, _ = np.polyfit(x[k - 1:k + 2], y[k - 1:k + 2], 2)
    return float(np.clip(-b / (2 * a), x[k - 1], x[k + 1])) if a < 0 else float(x[k])


def _band_pass(x: FloatArray, omega: float, zeta: float, dt: float) -> FloatArray:
    nyquist = np.pi / dt
    lo, hi = omega * max(1 - 2 * zeta, 0.2), min(omega * (1 + 2 * zeta), 0.95 * nyquist)
    sos = signal.butter(2, [lo / nyquist, hi / nyquist], btype="bandpass", output="sos")
    return signal.sosfiltfilt(sos, x)


def unlisted_terms(problem: Problem) -> Iterator[Fitted]:
    """A sparse regression over a library of products the catalogue does not name (``x_a *
    x_b``, ``x_a * u_j``, ``x_a**2``, ``u_j**2``): per equation, the single best term."""
    res, model = problem.residuals, problem.model
    observable = [i for i in range(len(model.state_names)) if res.observable[i]]
    variables = [(model.state_names[i], res.midpoint[:, i]) for i in observable]
    variables += [(n, res.u[:-1, j]) for j, n in enumerate(model.input_names)
                  if np.ptp(res.u[:, j]) > 0]
    library = [(f"{a}*{b}", va * vb)
               for (a, va), (b, vb) in itertools.combinations_with_replacement(variables, 2)]
    if not library:
        return
    names = [name for name, _ in library]
    theta = np.column_stack([column for _, column in library])
    fit = problem.fit
    theta_fit = theta[fit]
    norms = np.sum(theta_fit**2, axis=0)
    valid = norms > 0
    for i in _targets(problem):
        gain = np.where(valid, (theta_fit.T @ problem.error[fit, i]) ** 2
                        / np.maximum(norms, 1e-300), -1.0)
        k = int(np.argmax(gain))
        fitted = _single_row(problem, "unlisted", i, theta[:, k], {"expression": names[k]})
        if fitted is not None:
            fitted.multiplicity = len(library)
            yield fitted
