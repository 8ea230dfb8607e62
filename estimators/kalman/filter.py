"""The batched discrete-time Kalman filter.

Model (filterpy's names, the hydrofoil AKF paper's symbols in brackets)::

    x_{k+1} = F x_k + G u_k + c + w_k,    w_k ~ N(0, Q)    [Phi, G, WQ]
    y_k     = H x_k + d + v_k,            v_k ~ N(0, R)    [H, WR]

``c`` and ``d`` carry the trim of a model linearised about a point that is not the origin, so the
filter works in the model's absolute units. The update is in Joseph form and each covariance is
exactly symmetric, so it stays symmetric positive definite, also in float32. Every step is the
compiled kernels' (:mod:`estimators.kalman.kernels`), for filters holding a covariance each and
for filters sharing one alike.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel
from marine_envs.models.linear import dlqe

from ..base import Estimator, as_batch, check_covariance, check_measurement
from .design import (
    default_measurement_noise,
    default_process_noise,
    linearised_model,
    wrapped_channel_names,
)
from .kernels import follow_innovations, kernels

FloatArray = NDArray[np.floating]


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
        self._Q, self._R = self.Q.astype(t), self.R.astype(t)
        self._c, self._d = self.c.astype(t), self.d.astype(t)
        self._wrapped = np.isin(np.arange(m), self.angular)
        self._chi2_mean_weight = 0.05  # running mean over ~20 updates
        self._kernels = kernels(n, m)
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
        Phi, G, H, c, d = linearised_model(model, dt, measured, x_ref, u_ref)
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
        system = env.unwrapped.system
        Q = default_process_noise(system) if Q is None else Q
        R = default_measurement_noise(system) if R is None else R
        kwargs.setdefault("angular", wrapped_channel_names(system))
        return cls.from_model(system.model, system.dt, measured=system.channels, Q=Q, R=R,
                              x_ref=system.task.x_ref, u_ref=system.task.u_ref, **kwargs)

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
        x, P = np.empty_like(self.x), np.empty_like(self._P)
        choices, second = self._noise_choices()
        self._kernels.predict(self.F, self.G, self._c, choices, second, self.x,
                              _plain(u, self.dtype), self._P, x, P)
        self.x, self._P = x, P
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        y, valid = check_measurement(y, mask, self.measurement_names, self.batch_size, self.dtype)
        if not valid.all():  # each filter's own channels: a covariance each
            self._split()
        finite = self._update_compiled(_plain(y, self.dtype), valid)
        self._after_update(finite)
        return self.x, self.P

    @property
    def compiled(self) -> bool:
        """True: every filter is stepped by the compiled kernels (:mod:`estimators.kalman.kernels`,
        the filter's one implementation)."""
        return True

    def __getstate__(self) -> dict[str, Any]:
        # the kernels are compiled objects: looked up again (from the disk cache) on unpickling
        return {k: v for k, v in self.__dict__.items() if k != "_kernels"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._kernels = kernels(self._n, self.H.shape[0])

    def _update_compiled(self, y: FloatArray, valid: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """One Joseph-form update of every filter by the compiled kernel (the covariance's part
        once when it is shared); which stayed finite."""
        N, m = y.shape
        x, P = np.empty_like(self.x), np.empty_like(self._P)
        e, S = np.empty_like(y), np.empty((P.shape[0], m, m), dtype=self.dtype)
        self.nis, self.dof = np.empty(N), np.empty(N, dtype=np.intp)
        finite = np.empty(N, dtype=bool)
        self._kernels.update(self.H, self._R, self._d, self._wrapped, self.x, self._P, y, valid,
                             x, P, e, S, self.nis, self.dof, finite)
        self.x, self._P, self.innovation, self._S = x, P, e, S
        return finite

    # -- covariance sharing, statistics and health -----------------------------------------
    def _split(self) -> None:
        """Give every filter its own covariance."""
        if self._P.shape[0] != self.batch_size:
            self._P = np.repeat(self._P, self.batch_size, axis=0)

    def _try_merge(self) -> None:
        """Hold the covariance once again when every filter's has converged to the same."""
        P = self._P
        if P.shape[0] > 1 and not self._noise_varies():
            # compared as correlations: badly scaled states must agree in their own units too
            std = np.sqrt(np.abs(np.diagonal(P[0])))
            scale, ptp = np.outer(std, std), np.ptp(P, axis=0)
            with np.errstate(over="ignore"):  # a state known exactly: any spread is too much
                spread = np.divide(ptp, scale, out=np.where(ptp > 0, np.inf, 0.0),
                                   where=scale > 0)
            if spread.max() <= 16 * np.finfo(self.dtype).eps:
                self._P = P[:1].copy()

    def _noise_varies(self) -> bool:
        """Whether the filters' next predictions take different process noises."""
        return False

    def _noise_choices(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The process-noise covariances ``(k, n, n)`` a prediction picks from, and for each
        filter whether it takes the second."""
        return self._Q[None], self._all_first

    def _after_update(self, finite: NDArray[np.bool_]) -> None:
        """Merge covariances now and then, follow the innovation statistic, flag (and restart on
        request) the filters that diverged (``finite``: which have a finite x and P)."""
        self._updates += 1
        if self._updates % 64 == 0:
            self._try_merge()
        bad = np.empty(self.batch_size, dtype=bool)
        if follow_innovations(self.nis, self.dof, self._nis_mean, self._chi2_mean_weight,
                               self.divergence_ratio * self.H.shape[0], finite, bad):
            self.diverged = self.diverged | bad
            if self.reinitialise_diverged:
                self.reset(idx=np.flatnonzero(bad))
                self.diverged = self.diverged | bad

    def steady_state_covariance(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The stationary ``(P_predicted, P_updated)`` of the filter with every channel measured,
        from the discrete algebraic Riccati equation (:func:`marine_envs.models.linear.dlqe`)."""
        return dlqe(self.F.astype(float), self.H.astype(float), self.Q, self.R)


def _plain(a: NDArray, dtype: np.dtype) -> NDArray:
    """``a`` as a writable C-contiguous array of ``dtype`` (the one layout the kernels are
    compiled for: read-only or strided arrays would each compile a variant)."""
    if a.dtype == dtype and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=dtype, order="C")


def _read_only(a: NDArray, rows: int) -> NDArray:
    """A read-only view of ``a`` ``(k, ...)`` with ``rows`` rows (``k`` is 1 or ``rows``)."""
    if a.shape[0] != rows:
        return np.broadcast_to(a, (rows, *a.shape[1:]))
    view = a.view()
    view.flags.writeable = False
    return view
