"""Batched discrete-time Kalman filters: the textbook one and the hydrofoil AKF paper's AKF.

Model (filterpy's names, the paper's symbols in brackets)::

    x_{k+1} = F x_k + G u_k + c + w_k,    w_k ~ N(0, Q)    [Phi, G, WQ]
    y_k     = H x_k + d + v_k,            v_k ~ N(0, R)    [H, WR]

``c`` and ``d`` carry the trim of a model linearised about a point that is not the origin, so the
filter works in the model's absolute units. The update is in Joseph form and the covariance is
symmetrised after each step, so it stays symmetric positive definite, also in float32.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.stats
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel, zoh
from marine_envs.models.linear import dlqe
from marine_envs.sensors import GaussianNoise, Quantizer, WrapAngle

from .base import Estimator, as_batch, check_covariance, check_measurement

FloatArray = NDArray[np.floating]


def held_noise_covariance(A: ArrayLike, E: ArrayLike, dt: float,
                          disturbance_cov: ArrayLike) -> NDArray[np.float64]:
    """Process-noise covariance ``Q = Gamma_E Sigma Gamma_E'`` of disturbances ``d`` held over
    each period (``Gamma_E``: the :func:`~marine_envs.models.zoh` input matrix of ``E``), with
    ``Sigma`` their covariance."""
    E = np.atleast_2d(np.asarray(E, dtype=float))
    _, gamma = zoh(A, E, dt)
    sigma = check_covariance("disturbance_cov", disturbance_cov, E.shape[1])
    q = gamma @ sigma @ gamma.T
    return (q + q.T) / 2


def _wrap(a: FloatArray) -> FloatArray:
    return math.pi - (math.pi - a) % (2 * math.pi)


class KalmanFilter(Estimator):
    """A batch of ``N`` linear Kalman filters sharing one model.

    :param F, G, H: transition ``(n, n)``, input ``(n, n_u)`` and measurement ``(m, n)`` matrices.
    :param Q, R: process ``(n, n)`` and measurement ``(m, m)`` noise covariances (a vector is a
        diagonal), in the state's and the measurement's units squared.
    :param dt: period of one ``predict``, s (``F`` and ``G`` are for this period).
    :param c, d: constant terms of the transition and of the measurement (default 0).
    :param x0, P0: default initial estimate ``(n,)`` and covariance ``(n, n)`` of :meth:`reset`.
    :param state_names, measurement_names: for plots and wrappers.
    :param angular: measured channels (names or indices) that are angles wrapped to (-pi, pi]
        (e.g. a compass): their innovation is wrapped, so the estimate may run past +-pi.
    :param batch_size: number of filters ``N``.
    :param dtype: float64 (default) or float32.
    :param divergence_ratio: a filter is flagged ``diverged`` when its state or covariance is not
        finite or when a running mean (over ~20 updates) of its normalised innovation squared
        exceeds this many times its expected value (the number of measured channels).
    :param reinitialise_diverged: restart diverged filters from ``x0, P0`` automatically (the flag
        stays set until :meth:`reset`).
    """

    def __init__(self, F: ArrayLike, G: ArrayLike, H: ArrayLike, Q: ArrayLike, R: ArrayLike, *,
                 dt: float, c: ArrayLike | None = None, d: ArrayLike | None = None,
                 x0: ArrayLike | None = None, P0: ArrayLike | None = None,
                 state_names: Sequence[str] | None = None,
                 measurement_names: Sequence[str] | None = None,
                 angular: Sequence[str | int] = (), batch_size: int = 1,
                 dtype: type | np.dtype = np.float64, divergence_ratio: float = 10.0,
                 reinitialise_diverged: bool = False) -> None:
        F = np.atleast_2d(np.asarray(F, dtype=float))
        n = F.shape[0]
        G = np.asarray(G, dtype=float)
        G = G[:, None] if G.ndim == 1 else G
        H = np.atleast_2d(np.asarray(H, dtype=float))
        m = H.shape[0]
        if F.shape != (n, n) or H.shape[1] != n or G.ndim != 2 or G.shape[0] != n:
            raise ValueError(f"shapes do not match: F {F.shape}, G {np.shape(G)}, H {H.shape} "
                             f"(F must be n x n, G n x n_u, H m x n)")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
        if not divergence_ratio > 1:
            raise ValueError(f"divergence_ratio={divergence_ratio!r} is invalid: must be > 1")
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype={dtype!r} is invalid: float32 or float64")
        self.state_names = tuple(state_names or (f"x{i}" for i in range(n)))
        self.measurement_names = tuple(measurement_names or (f"y{i}" for i in range(m)))
        if len(self.state_names) != n or len(self.measurement_names) != m:
            raise ValueError(f"{len(self.state_names)} state names for {n} states or "
                             f"{len(self.measurement_names)} measurement names for {m} rows of H")
        self.dt = float(dt)
        self.Q = check_covariance("Q", Q, n)
        self.R = check_covariance("R", R, m)
        if np.linalg.eigvalsh(self.R).min() <= 0:
            raise ValueError("R must be positive definite: every measurement has some noise")
        self.c = np.zeros(n) if c is None else as_batch("c", c, 1, n)[0]
        self.d = np.zeros(m) if d is None else as_batch("d", d, 1, m)[0]
        self.x0 = np.zeros(n) if x0 is None else as_batch("x0", x0, 1, n)[0].copy()
        self.P0 = np.eye(n) if P0 is None else check_covariance("P0", P0, n)
        self.angular = np.array([self.measurement_names.index(a) if isinstance(a, str) else a
                                 for a in angular], dtype=np.intp)
        self.divergence_ratio = float(divergence_ratio)
        self.reinitialise_diverged = reinitialise_diverged
        t = self.dtype.type
        self.F, self.G, self.H = F.astype(t), G.astype(t), H.astype(t)
        self._FT, self._GT, self._HT = self.F.T.copy(), self.G.T.copy(), self.H.T.copy()
        self._Q, self._R = self.Q.astype(t), self.R.astype(t)
        self._c, self._d = self.c.astype(t), self.d.astype(t)
        self._I = np.eye(n, dtype=t)
        self._chi2_mean_weight = 0.05  # running mean over ~20 updates
        self.bind(batch_size)

    # -- construction from the project's models and environments --------------------------
    @classmethod
    def from_model(cls, model: VehicleModel, dt: float, *, measured: Sequence[str],
                   Q: ArrayLike, R: ArrayLike, x_ref: ArrayLike | None = None,
                   u_ref: ArrayLike | None = None, **kwargs: Any) -> KalmanFilter:
        """The filter of a model linearised about ``(x_ref, u_ref)`` (default: its nominal point)
        and discretised with a zero-order hold over ``dt`` s.

        :param measured: the measured outputs, by name (``model.output_names``).
        :param Q: process-noise covariance per period (see :func:`held_noise_covariance`).
        :param R: measurement-noise covariance.
        :param kwargs: passed to the constructor (``P0``, ``angular``, ``batch_size``, ...).
        """
        x_ref = model.x0 if x_ref is None else np.asarray(x_ref, dtype=float)
        u_ref = model.u0 if u_ref is None else np.asarray(u_ref, dtype=float)
        A, B, _ = model.linearize(x_ref, u_ref)
        Phi, Gamma = zoh(A, np.column_stack([B, model.rhs(x_ref, u_ref)]), dt)
        G, drift = Gamma[:, :-1], Gamma[:, -1]
        c = x_ref - Phi @ x_ref - G @ u_ref + drift
        H, d = _output_matrix(model, measured, x_ref)
        kwargs.setdefault("x0", x_ref)
        return cls(Phi, G, H, Q=Q, R=R, dt=dt, c=c, d=d, state_names=model.state_names,
                   measurement_names=measured, **kwargs)

    @classmethod
    def for_env(cls, env: Any, Q: ArrayLike | None = None, R: ArrayLike | None = None,
                **kwargs: Any) -> KalmanFilter:
        """A filter for a marine environment: its model linearised at the task's reference, its
        control period, its sensors' channels.

        :param Q: process noise per control period; default: the covariance of the env's own
            disturbances (sampled from one episode of a fixed seed) held over a period.
        :param R: measurement noise; default: each sensor's noise variance plus its quantization
            step squared over 12.
        """
        sim = env.unwrapped.sim
        model = sim.model
        Q = default_process_noise(sim) if Q is None else Q
        R = default_measurement_noise(sim) if R is None else R
        wrapped = [c for c, w in zip(sim.sensors.channels, _wrapped_channels(sim), strict=True)
                   if w]
        kwargs.setdefault("angular", wrapped)
        return cls.from_model(model, sim.dt, measured=sim.sensors.channels, Q=Q, R=R,
                              x_ref=sim.task.x_ref, u_ref=sim.task.u_ref, **kwargs)

    # -- the estimator contract ------------------------------------------------------------
    # The covariance does not depend on the data: filters started alike and measured alike share
    # it. It is then held once, shape (1, n, n), and every filter's gain is one matrix, which
    # makes a batch of N cost little more than one filter. Resets of some filters, missing
    # channels or per-filter process noise split it into (N, n, n); it is merged again once the
    # filters' covariances have converged to the same values.
    @property
    def P(self) -> FloatArray:
        """Covariance of each filter's estimate, ``(N, n, n)`` (a read-only view)."""
        return np.broadcast_to(self._P, (self.batch_size, self._n, self._n))

    @property
    def innovation_cov(self) -> FloatArray:
        """Covariance ``S = H P_pred H' + R`` of the last innovation, ``(N, m, m)``."""
        return np.broadcast_to(self._S, (self.batch_size, *self._S.shape[1:]))

    @property
    def shared_covariance(self) -> bool:
        """Whether every filter of the batch has the same covariance (held once)."""
        return self._P.shape[0] == 1

    def bind(self, batch_size: int) -> None:
        if not (isinstance(batch_size, int | np.integer) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: an integer >= 1")
        n, m = self.F.shape[0], self.H.shape[0]
        self._n = n
        self.x = np.tile(self.x0.astype(self.dtype), (batch_size, 1))
        self._P = self.P0.astype(self.dtype)[None].copy()
        self._S = self._R[None].copy()
        self.innovation = np.zeros((batch_size, m), dtype=self.dtype)
        self.nis = np.zeros(batch_size)
        self.dof = np.zeros(batch_size, dtype=np.intp)
        self._nis_mean = np.full(batch_size, float(m))
        self.diverged = np.zeros(batch_size, dtype=bool)
        self._updates = 0

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        rows = np.arange(self.batch_size) if idx is None else np.atleast_1d(np.asarray(idx))
        if rows.dtype == bool:
            rows = np.flatnonzero(rows)
        rows = np.unique(rows)
        x = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        if x.shape not in ((self._n,), (rows.size, self._n)) or not np.isfinite(x).all():
            raise ValueError(f"x0 must be {self._n} finite values or ({rows.size}, {self._n}); "
                             f"got shape {x.shape}")
        P = self.P0 if P0 is None else check_covariance("P0", P0, self._n)
        self.x[rows] = x
        if rows.size == self.batch_size:
            self._P = P.astype(self.dtype)[None].copy()
        elif rows.size:
            self._split()
            self._P[rows] = P
        self.innovation[rows] = 0
        self._nis_mean[rows] = self.H.shape[0]
        self.diverged[rows] = False

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        if dt is not None and not math.isclose(dt, self.dt):
            raise ValueError(f"dt={dt} differs from the filter's period {self.dt} s")
        u = as_batch("u", u, self.batch_size, self.G.shape[1]).astype(self.dtype, copy=False)
        self.x = self.x @ self._FT + u @ self._GT + self._c
        Q = self._process_noise()
        if Q.shape[0] > self._P.shape[0]:
            self._split()
        P = self.F @ self._P @ self._FT + Q
        self._P = (P + P.transpose(0, 2, 1)) * 0.5
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        N, m = self.batch_size, self.H.shape[0]
        y, valid = check_measurement(y, mask, self.measurement_names, N, self.dtype)
        every = bool(valid.all())
        e = y - (self.x @ self._HT + self._d)
        if self.angular.size:
            e[:, self.angular] = _wrap(e[:, self.angular])
        if every:
            H, R = self.H[None], self._R[None]
        else:  # missing channels: zero rows of H and unit noise give them exactly zero gain
            self._split()
            e = np.where(valid, e, 0)
            H = self.H * valid[:, :, None]
            both = valid[:, :, None] & valid[:, None, :]
            R = (np.where(both, self._R, 0) + np.where(valid, 0, 1)[:, :, None] * np.eye(m))
            R = R.astype(self.dtype)
        HT = H.transpose(0, 2, 1)
        PHt = self._P @ HT
        S = H @ PHt + R
        n = self._n
        if self.shared_covariance:  # one solve: S^-1 [H P, e_1 ... e_N]
            sol = np.linalg.solve(S[0], np.concatenate([PHt[0].T, e.T], axis=1))
            K, S_inv_e = sol[:, :n].T[None], sol[:, n:].T
            self.x = self.x + e @ K[0].T
        else:  # one batched solve: S_i^-1 [H P_i, e_i]
            rhs = np.concatenate([PHt.transpose(0, 2, 1), e[:, :, None]], axis=2)
            sol = np.linalg.solve(S, rhs)
            K, S_inv_e = sol[:, :, :n].transpose(0, 2, 1), sol[:, :, n]
            self.x = self.x + (K @ e[:, :, None])[:, :, 0]
        IKH = self._I - K @ H
        P = IKH @ self._P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
        self._P = (P + P.transpose(0, 2, 1)) * 0.5
        self.innovation, self._S = e, S
        self.nis = np.einsum("ij,ij->i", e, S_inv_e).astype(float)
        self.dof = np.full(N, m) if every else valid.sum(axis=1)
        self._after_update()
        return self.x, self.P

    # -- covariance sharing, statistics and health -----------------------------------------
    def _split(self) -> None:
        """Give every filter its own covariance."""
        if self._P.shape[0] != self.batch_size:
            self._P = np.repeat(self._P, self.batch_size, axis=0)

    def _try_merge(self) -> None:
        """Hold the covariance once again when every filter's has converged to the same."""
        P = self._P
        if P.shape[0] > 1 and self._process_noise().shape[0] == 1:
            # compared as correlations: badly scaled states must agree in their own units too
            std = np.sqrt(np.abs(np.diagonal(P[0]))) + np.finfo(self.dtype).tiny
            spread = np.ptp(P, axis=0) / np.outer(std, std)
            if spread.max() <= 16 * np.finfo(self.dtype).eps:
                self._P = P[:1].copy()

    def _process_noise(self) -> FloatArray:
        return self._Q[None]

    def _after_update(self) -> None:
        self._updates += 1
        if self._updates % 64 == 0:
            self._try_merge()
        w = self._chi2_mean_weight
        seen = self.dof > 0
        self._nis_mean = np.where(seen, (1 - w) * self._nis_mean + w * self.nis, self._nis_mean)
        finite = np.isfinite(self.x).all(axis=1) & np.isfinite(self._P).all(axis=(1, 2))
        bad = ~finite | (self._nis_mean > self.divergence_ratio * self.H.shape[0])
        if bad.any():
            self.diverged = self.diverged | bad
            if self.reinitialise_diverged:
                self.reset(idx=np.flatnonzero(bad))
                self.diverged = self.diverged | bad

    def steady_state_covariance(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The stationary ``(P_predicted, P_updated)`` of the filter with every channel measured,
        from the discrete algebraic Riccati equation (:func:`marine_envs.models.linear.dlqe`)."""
        return dlqe(self.F.astype(float), self.H.astype(float), self.Q, self.R)


class AdaptiveKalmanFilter(KalmanFilter):
    """The hydrofoil AKF paper's adaptive Kalman filter: the process noise switches with the
    innovation test.

    After each update the statistic ``phi = e' Ce^-1 e`` (``Ce = H P_pred H' + WR``), chi-square
    with ``m`` degrees of freedom when the filter's model is right, picks the process noise of the
    next prediction: ``Q_max`` above the ``upper_quantile`` (0.90) of chi2(m), ``Q_min`` below the
    ``lower_quantile`` (0.50), else unchanged. It starts at ``Q_min``.

    :param Q, Q_max: the two process-noise covariances ``Q_min`` and ``Q_max`` (the hydrofoil AKF
        paper: WQmin = diag(1, 1, 0.3, 0.3), WQmax = diag(10, 10, 3, 3)).
    :param upper_quantile, lower_quantile: the thresholds' chi-square probabilities.
    Other parameters as :class:`KalmanFilter`.

    ``fired`` ``(N,)`` says whose statistic exceeded the upper threshold at the last update, and
    ``high`` whose process noise is ``Q_max`` now.
    """

    def __init__(self, F: ArrayLike, G: ArrayLike, H: ArrayLike, Q: ArrayLike, R: ArrayLike, *,
                 Q_max: ArrayLike, upper_quantile: float = 0.90, lower_quantile: float = 0.50,
                 **kwargs: Any) -> None:
        if not 0 < lower_quantile <= upper_quantile < 1:
            raise ValueError(f"quantiles lower={lower_quantile}, upper={upper_quantile} are "
                             "invalid: need 0 < lower <= upper < 1")
        self.upper_quantile, self.lower_quantile = upper_quantile, lower_quantile
        super().__init__(F, G, H, Q, R, **kwargs)
        self.Q_min, self.Q_max = self.Q, check_covariance("Q_max", Q_max, self._n)
        self._Q_pair = np.stack([self.Q_min, self.Q_max]).astype(self.dtype)
        dof = np.arange(self.H.shape[0] + 1)
        # thresholds by the number of channels measured at the update (0 measured: never fires)
        self._upper = np.r_[np.inf, scipy.stats.chi2.ppf(upper_quantile, dof[1:])]
        self._lower = np.r_[-np.inf, scipy.stats.chi2.ppf(lower_quantile, dof[1:])]

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.high = np.zeros(batch_size, dtype=bool)
        self.fired = np.zeros(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        super().reset(x0, P0, idx)
        rows = slice(None) if idx is None else np.atleast_1d(np.asarray(idx))
        self.high[rows], self.fired[rows] = False, False

    def _process_noise(self) -> FloatArray:
        if self.high.all() or not self.high.any():
            return self._Q_pair[1 if self.high[0] else 0][None]
        return self._Q_pair[self.high.astype(np.intp)]

    def _after_update(self) -> None:
        self.fired = self.nis > self._upper[self.dof]
        below = self.nis < self._lower[self.dof]
        self.high = np.where(self.fired, True, np.where(below, False, self.high))
        super()._after_update()


def _output_matrix(model: VehicleModel, measured: Sequence[str],
                   x_ref: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """``(H, d)`` with ``output[measured] ~= H x + d`` near ``x_ref`` (exact for linear outputs)."""
    unknown = sorted(set(measured) - set(model.output_names))
    if unknown:
        raise ValueError(f"measured channel(s) {unknown} are not outputs of model "
                         f"{model.name!r}: {', '.join(model.output_names)}")
    rows = [model.output_names.index(c) for c in measured]
    if model.output_names == model.state_names:
        H = np.eye(len(x_ref))[rows]
        return H, np.zeros(len(rows))
    steps = 1e-6 * np.maximum(1.0, np.abs(x_ref))
    plus = model.output(x_ref + np.diag(steps))[:, rows]
    minus = model.output(x_ref - np.diag(steps))[:, rows]
    H = ((plus - minus) / (2 * steps[:, None])).T
    return H, model.output(x_ref[None])[0, rows] - H @ x_ref


def _wrapped_channels(sim: Any) -> list[bool]:
    wrapped = np.zeros(len(sim.sensors.channels), dtype=bool)
    for stage in sim.sensors.stages:
        if isinstance(stage, WrapAngle):
            wrapped[stage.idx] = True
    return wrapped.tolist()


def default_measurement_noise(sim: Any) -> NDArray[np.float64]:
    """Each channel's noise variance plus its quantization step squared over 12 (diagonal)."""
    var = np.zeros(len(sim.sensors.channels))
    for stage in sim.sensors.stages:
        if isinstance(stage, GaussianNoise):
            var += np.asarray(stage.std, dtype=float).ravel() ** 2
        elif isinstance(stage, Quantizer):
            var[stage.idx] += stage.mu[0] ** 2 / 12
    floor = 1e-12 * max(1.0, var.max())
    return np.diag(np.maximum(var, floor))


def default_process_noise(sim: Any, steps: int = 2000, seed: int = 0) -> NDArray[np.float64]:
    """The covariance of the environment's disturbances over one ``steps``-long run of a fixed
    seed, held over each control period and mapped through the model's ``E`` at the reference."""
    model = sim.model
    n_d = len(model.disturbance_names)
    A, _, E = model.linearize(sim.task.x_ref, sim.task.u_ref)
    if sim.disturbances is None or n_d == 0:
        sigma = np.zeros((n_d, n_d))
    else:
        source = copy.deepcopy(sim.disturbances)
        source.bind(1)
        source.reset(np.array([0]), [np.random.default_rng(seed)])
        samples = np.concatenate([source.step() for _ in range(steps)])
        sigma = np.atleast_2d(np.cov(samples, rowvar=False))
    n = A.shape[0]
    Q = held_noise_covariance(A, E, sim.dt, sigma) if n_d else np.zeros((n, n))
    # a floor keeps every state's prediction honest about the model's own errors; per state, in
    # its own unit (a trace would mix N^2 of a bias with rad^2 of a heading)
    return Q + np.diag(1e-9 * np.maximum(1.0, np.diag(Q)))
