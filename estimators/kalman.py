"""Batched discrete-time Kalman filters: the textbook one and the hydrofoil AKF paper's AKF.

Model (filterpy's names, the paper's symbols in brackets)::

    x_{k+1} = F x_k + G u_k + c + w_k,    w_k ~ N(0, Q)    [Phi, G, WQ]
    y_k     = H x_k + d + v_k,            v_k ~ N(0, R)    [H, WR]

``c`` and ``d`` carry the trim of a model linearised about a point that is not the origin, so the
filter works in the model's absolute units. The update is in Joseph form and the covariance is
symmetrised after each step, so it stays symmetric positive definite, also in float32.

Filters that hold a covariance each (some channels missing, resets of some filters, the adaptive
filter's process noise) are stepped one filter at a time by compiled kernels (numba, the matrix
sizes fixed at compile time); filters that share one covariance are stepped in numpy, where one
gain serves the batch. The numpy code of the per-filter case stays as the reference the kernels
are tested against (:meth:`KalmanFilter.run_in_numpy`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from functools import cache
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.compiled import jit, local_array
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
        self._wrapped = np.isin(np.arange(m), self.angular)
        self._chi2_mean_weight = 0.05  # running mean over ~20 updates
        self._kernels: _Kernels | None = _kernels(n, m)
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
        return _read_only(self._P, self.batch_size)

    @property
    def innovation_cov(self) -> FloatArray:
        """Covariance ``S = H P_pred H' + R`` of the last innovation, ``(N, m, m)``."""
        return _read_only(self._S, self.batch_size)

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
        self._all_first = np.zeros(batch_size, dtype=bool)  # no filter takes the second Q
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
        u = as_batch("u", u, self.batch_size, self.G.shape[1])
        if self._noise_varies():
            self._split()
        if self._per_filter_kernels():
            x, P = np.empty_like(self.x), np.empty_like(self._P)
            choices, second = self._noise_choices()
            self._kernels.predict(self.F, self.G, self._c, choices, second, self.x,
                                  _plain(u, self.dtype), self._P, x, P)
            self.x, self._P = x, P
            return self.x
        u = u.astype(self.dtype, copy=False)
        self.x = self.x @ self._FT + u @ self._GT + self._c
        P = self.F @ self._P @ self._FT + self._process_noise()
        self._P = (P + P.transpose(0, 2, 1)) * 0.5
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        y, valid = check_measurement(y, mask, self.measurement_names, self.batch_size, self.dtype)
        every = bool(valid.all())
        if not every:
            self._split()
        if self._per_filter_kernels():
            finite = self._update_compiled(_plain(y, self.dtype), valid)
        else:
            finite = self._update_numpy(y, valid, every)
        self._after_update(finite)
        return self.x, self.P

    @property
    def compiled(self) -> bool:
        """True when filters holding a covariance each are stepped by the compiled kernels."""
        return self._kernels is not None

    def run_in_numpy(self) -> None:
        """Do the predictions and updates in numpy from now on, also for filters holding a
        covariance each (the reference the compiled kernels are tested against; slower)."""
        self._kernels = None

    def _per_filter_kernels(self) -> bool:
        return self._kernels is not None and self._P.shape[0] == self.batch_size

    def __getstate__(self) -> dict[str, Any]:
        # the kernels are compiled objects: looked up again (from the disk cache) on unpickling
        return {**self.__dict__, "_kernels": self._kernels is not None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._kernels = _kernels(self._n, self.H.shape[0]) if state["_kernels"] else None

    def _update_compiled(self, y: FloatArray, valid: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """One Joseph-form update of every filter by the compiled kernel; which stayed finite."""
        N, m = y.shape
        x, P = np.empty_like(self.x), np.empty_like(self._P)
        e, S = np.empty_like(y), np.empty((N, m, m), dtype=self.dtype)
        self.nis, self.dof = np.empty(N), np.empty(N, dtype=np.intp)
        finite = np.empty(N, dtype=bool)
        self._kernels.update(self.H, self._R, self._d, self._wrapped, self.x, self._P, y, valid,
                             x, P, e, S, self.nis, self.dof, finite)
        self.x, self._P, self.innovation, self._S = x, P, e, S
        return finite

    def _update_numpy(self, y: FloatArray, valid: NDArray[np.bool_], every: bool
                      ) -> NDArray[np.bool_]:
        """The update in numpy (one gain when the covariance is shared); which stayed finite."""
        N, m = self.batch_size, self.H.shape[0]
        e = y - (self.x @ self._HT + self._d)
        if self.angular.size:
            e[:, self.angular] = _wrap(e[:, self.angular])
        if every:
            H, R = self.H[None], self._R[None]
        else:  # missing channels: zero rows of H and unit noise give them exactly zero gain
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
        return np.isfinite(self.x).all(axis=1) & np.isfinite(self._P).all(axis=(1, 2))

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
            std = np.sqrt(np.abs(np.diagonal(P[0])))
            scale, ptp = np.outer(std, std), np.ptp(P, axis=0)
            with np.errstate(over="ignore"):  # a state known exactly: any spread is too much
                spread = np.divide(ptp, scale, out=np.where(ptp > 0, np.inf, 0.0),
                                   where=scale > 0)
            if spread.max() <= 16 * np.finfo(self.dtype).eps:
                self._P = P[:1].copy()

    def _process_noise(self) -> FloatArray:
        """The process-noise covariance of each filter's next prediction, ``(1, n, n)`` when
        they share one."""
        return self._Q[None]

    def _noise_varies(self) -> bool:
        """Whether the filters' next predictions take different process noises."""
        return False

    def _noise_choices(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The process-noise covariances ``(k, n, n)`` a prediction picks from, and for each
        filter whether it takes the second (the compiled kernels' form of
        :meth:`_process_noise`)."""
        return self._Q[None], self._all_first

    def _after_update(self, finite: NDArray[np.bool_]) -> None:
        """Merge covariances now and then, follow the innovation statistic, flag (and restart on
        request) the filters that diverged (``finite``: which have a finite x and P)."""
        self._updates += 1
        if self._updates % 64 == 0:
            self._try_merge()
        bad = np.empty(self.batch_size, dtype=bool)
        if _follow_innovations(self.nis, self.dof, self._nis_mean, self._chi2_mean_weight,
                               self.divergence_ratio * self.H.shape[0], finite, bad):
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
        import scipy.stats  # (here: `import estimators` need not load it)

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
        if not self._noise_varies():
            return self._Q_pair[1 if self.high[0] else 0][None]
        return self._Q_pair[self.high.astype(np.intp)]

    def _noise_varies(self) -> bool:
        return bool(self.high.any() and not self.high.all())

    def _noise_choices(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        return self._Q_pair, self.high

    def _after_update(self, finite: NDArray[np.bool_]) -> None:
        self.high, self.fired = self.high.copy(), np.empty(self.batch_size, dtype=bool)
        _switch_noise(self.nis, self.dof, self._upper, self._lower, self.high, self.fired)
        super()._after_update(finite)


# -- the per-filter step, compiled ------------------------------------------------------------
# A filter at a time, with the matrix sizes fixed at compile time: the loops are unrolled and the
# scratch matrices live on the stack, so a covariance per filter costs what its arithmetic costs
# (numpy's batched small-matrix calls cost more in overhead than in arithmetic). Sums are in
# float64 also for float32 filters. The same formulas as the numpy code: the missing channels get
# zero rows of H and unit noise (hence zero gain), the update is in Joseph form, and each
# covariance is computed once per pair (i, j), so it is exactly symmetric.
class _Kernels(NamedTuple):
    """The compiled per-filter steps of filters of ``n`` states and ``m`` channels.

    ``predict(F, G, c, Qs, second, x, u, P, x_out, P_out)``: ``x_out = F x + G u + c`` and
    ``P_out = F P F' + Q`` per filter, ``Q = Qs[1]`` where ``second`` else ``Qs[0]``.

    ``update(H, R, d, wrapped, x, P, y, valid, x_out, P_out, e, S, nis, dof, finite)``: the
    Joseph-form update with the ``valid`` channels of ``y``, the innovation (0 where missing;
    wrapped to (-pi, pi] where ``wrapped``), its covariance, its normalised square, the number of
    channels used and whether ``x_out`` and ``P_out`` are finite, per filter.
    """

    predict: Callable[..., None]
    update: Callable[..., None]


@cache
def _kernels(n: int, m: int) -> _Kernels:
    """The kernels of ``n`` states and ``m`` channels (compiled on first use, cached on disk)."""
    nn, nm, mm = n * n, n * m, m * m
    # the compiled functions they call are closure cells, not globals: the disk cache's key
    # visits a function's globals in the order of a set of names, which changes from process to
    # process (a miss each time) once there are two; closure cells have a fixed order
    stack, predict_one = local_array, _predict_one
    model, covariance, cholesky, whitened = (_masked_model, _innovation_covariance, _cholesky,
                                             _whitened_square)
    gain, corrected, joseph = _gain, _corrected, _joseph

    @jit
    def predict(F, G, c, Qs, second, x, u, P, x_out, P_out):
        FP = stack(nn)
        switching = Qs.shape[0] > 1
        for b in range(x.shape[0]):
            Q = Qs[1] if switching and second[b] else Qs[0]
            predict_one(F, G, c, Q, x[b], u[b], P[b], x_out[b], P_out[b], FP, n)

    @jit
    def update(H, R, d, wrapped, x, P, y, valid, x_out, P_out, e, S, nis, dof, finite):
        Hm, Rm, U, L = stack(nm), stack(mm), stack(nm), stack(mm)
        K, KR, A, AP = stack(nm), stack(nm), stack(nn), stack(nn)
        inv, z = stack(m), stack(m)
        for b in range(x.shape[0]):
            dof[b] = model(H, R, d, wrapped, x[b], y[b], valid[b], e[b], Hm, Rm, n, m)
            covariance(P[b], Hm, Rm, U, L, S[b], n, m)
            cholesky(L, inv, m)
            nis[b] = whitened(e[b], L, inv, z, m)
            gain(U, L, inv, K, n, m)
            finite[b] = (corrected(x[b], K, e[b], x_out[b], n, m)
                         & joseph(P[b], Hm, Rm, K, A, AP, KR, P_out[b], n, m))

    return _Kernels(predict, update)


@jit
def _predict_one(F, G, c, Q, x, u, P, x_out, P_out, FP, n):
    """One filter's prediction (``FP``: scratch of ``n * n``)."""
    for i in range(n):
        t = c[i]
        for k in range(n):
            t += F[i, k] * x[k]
        for k in range(u.size):
            t += G[i, k] * u[k]
        x_out[i] = t
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += F[i, k] * P[k, j]
            FP[i * n + j] = t
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for k in range(n):
                t += FP[i * n + k] * F[j, k]
            t += Q[i, j]
            P_out[i, j] = t
            P_out[j, i] = t


@jit
def _masked_model(H, R, d, wrapped, x, y, valid, e, Hm, Rm, n, m):
    """The innovation ``e`` of one filter (0 where missing), ``Hm`` (``m x n``, rows of the
    missing channels 0) and ``Rm`` (``m x m``, the valid channels' noise, identity for the
    missing); returns the number of valid channels."""
    count = 0
    for a in range(m):
        t = d[a]
        for k in range(n):
            t += H[a, k] * x[k]
        r = y[a] - t
        if wrapped[a]:
            r = math.pi - (math.pi - r) % (2 * math.pi)
        e[a] = r if valid[a] else 0.0
        count += valid[a]
        for k in range(n):
            Hm[a * n + k] = H[a, k] if valid[a] else 0.0
        for c in range(m):
            both = valid[a] and valid[c]
            Rm[a * m + c] = R[a, c] if both else (1.0 if a == c else 0.0)
    return count


@jit
def _innovation_covariance(P, Hm, Rm, U, L, S, n, m):
    """``U = P Hm'`` (``n x m``) and ``S = Hm U + Rm``, written to ``S`` and to the lower
    triangle of ``L``."""
    for i in range(n):
        for a in range(m):
            t = 0.0
            for k in range(n):
                t += P[i, k] * Hm[a * n + k]
            U[i * m + a] = t
    for a in range(m):
        for c in range(a + 1):
            t = 0.0
            for k in range(n):
                t += Hm[a * n + k] * U[k * m + c]
            t += Rm[a * m + c]
            L[a * m + c] = t
            S[a, c] = t
            S[c, a] = t


@jit
def _cholesky(L, inv, m):
    """The Cholesky factor of the lower triangle of ``L``, in place, and the reciprocals of its
    diagonal in ``inv`` (a matrix that is not positive definite gives NaN)."""
    for c in range(m):
        t = L[c * m + c]
        for k in range(c):
            t -= L[c * m + k] * L[c * m + k]
        L[c * m + c] = math.sqrt(t)
        inv[c] = 1.0 / L[c * m + c]
        for a in range(c + 1, m):
            t = L[a * m + c]
            for k in range(c):
                t -= L[a * m + k] * L[c * m + k]
            L[a * m + c] = t * inv[c]


@jit
def _whitened_square(e, L, inv, z, m):
    """``e' S^-1 e = |L^-1 e|^2`` (``z``: scratch of ``m``)."""
    total = 0.0
    for a in range(m):
        t = e[a]
        for k in range(a):
            t -= L[a * m + k] * z[k]
        z[a] = t * inv[a]
        total += z[a] * z[a]
    return total


@jit
def _gain(U, L, inv, K, n, m):
    """``K = U S^-1`` (``n x m``), each row solving ``L L' k = u``."""
    for i in range(n):
        for a in range(m):
            t = U[i * m + a]
            for k in range(a):
                t -= L[a * m + k] * K[i * m + k]
            K[i * m + a] = t * inv[a]
        for a in range(m - 1, -1, -1):
            t = K[i * m + a]
            for k in range(a + 1, m):
                t -= L[k * m + a] * K[i * m + k]
            K[i * m + a] = t * inv[a]


@jit
def _corrected(x, K, e, x_out, n, m):
    """``x_out = x + K e``; whether it is finite."""
    finite = True
    for i in range(n):
        t = x[i]
        for a in range(m):
            t += K[i * m + a] * e[a]
        x_out[i] = t
        finite = finite and np.isfinite(t)
    return finite


@jit
def _joseph(P, Hm, Rm, K, A, AP, KR, P_out, n, m):
    """``P_out = (I - K Hm) P (I - K Hm)' + K Rm K'``; whether it is finite (``A``, ``AP``,
    ``KR``: scratch)."""
    for i in range(n):
        for j in range(n):
            t = 1.0 if i == j else 0.0
            for a in range(m):
                t -= K[i * m + a] * Hm[a * n + j]
            A[i * n + j] = t
    for i in range(n):
        for j in range(n):
            t = 0.0
            for k in range(n):
                t += A[i * n + k] * P[k, j]
            AP[i * n + j] = t
        for a in range(m):
            t = 0.0
            for c in range(m):
                t += K[i * m + c] * Rm[c * m + a]
            KR[i * m + a] = t
    finite = True
    for i in range(n):
        for j in range(i, n):
            t = 0.0
            for k in range(n):
                t += AP[i * n + k] * A[j * n + k]
            for a in range(m):
                t += KR[i * m + a] * K[j * m + a]
            P_out[i, j] = t
            P_out[j, i] = t
            finite = finite and np.isfinite(t)
    return finite


def _plain(a: NDArray, dtype: np.dtype) -> NDArray:
    """``a`` as a writable C-contiguous array of ``dtype`` (the one layout the kernels are
    compiled for: read-only or strided arrays would each compile a variant)."""
    if a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=dtype, order="C")


@jit
def _follow_innovations(nis, dof, nis_mean, weight, limit, finite, bad):
    """Fold each filter's normalised innovation squared into its running mean (in place; a
    filter that measured nothing keeps its mean) and mark in ``bad`` the filters not ``finite``
    or with a mean above ``limit``; returns whether any is bad."""
    any_bad = False
    for b in range(nis.size):
        if dof[b] > 0:
            nis_mean[b] = (1 - weight) * nis_mean[b] + weight * nis[b]
        bad[b] = not finite[b] or nis_mean[b] > limit
        any_bad = any_bad or bad[b]
    return any_bad


@jit
def _switch_noise(nis, dof, upper, lower, high, fired):
    """The adaptive filter's test: ``fired`` where the statistic exceeds the upper threshold for
    its degrees of freedom; ``high`` (in place) set there, cleared below the lower one."""
    for b in range(nis.size):
        fired[b] = nis[b] > upper[dof[b]]
        if fired[b]:
            high[b] = True
        elif nis[b] < lower[dof[b]]:
            high[b] = False


def _read_only(a: NDArray, rows: int) -> NDArray:
    """A read-only view of ``a`` ``(k, ...)`` with ``rows`` rows (``k`` is 1 or ``rows``)."""
    if a.shape[0] != rows:
        return np.broadcast_to(a, (rows, *a.shape[1:]))
    view = a.view()
    view.flags.writeable = False
    return view


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
