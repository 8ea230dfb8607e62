"""Output-error fit: simulated outputs fitted to the measured ones (initial states included) by
``scipy.optimize.least_squares``, the simulations of all segments and parameter perturbations
batched in one pass over time (``_Simulation``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.optimize

from marine_envs.models import VehicleModel
from marine_envs.models.integrate import rk4

from .data import FloatArray, Segment, _initial_state
from .result import _pinv


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
            x = rk4(lambda z, _t, u=u, d=d: f(z, u, d), x, dt, self.substeps)
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
