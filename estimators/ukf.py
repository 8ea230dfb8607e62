"""The unscented Kalman filter: the extended Kalman filter's interface without Jacobians.

The mean and covariance are carried through the nonlinear dynamics and measurement by sigma
points (the spherical cubature rule); the statistical linearisation it records as its
``transition`` makes :func:`estimators.ekf.rts_smooth` the unscented RTS smoother.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from .base import check_measurement
from .ekf import ExtendedKalmanFilter, FloatArray
from .kalman import _wrap


class UnscentedKalmanFilter(ExtendedKalmanFilter):
    """The unscented variant: no Jacobians; the mean and covariance are carried through the
    nonlinear dynamics and measurement by ``2 L`` sigma points ``x +- sqrt(L) columns of
    chol(P)`` with equal weights (the spherical cubature rule: no negative weight, so the
    covariance stays positive definite for any state size ``L = n + p``).

    Same arguments, attributes and offline methods as :class:`ExtendedKalmanFilter` (``jacobian``
    and ``parameter_jacobian`` are not used). Its ``transition`` is the statistical
    linearisation ``Phi = C' P^-1`` (``C`` the cross covariance of the sigma points before and
    after the step), with which :func:`rts_smooth` is the unscented RTS smoother. Each step costs
    ``2 L`` evaluations of ``f`` per RK4 stage.
    """

    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        u, dt = self._input(u, dt)
        X = _sigma_points(self.x, self.P)  # (N, 2L, L)
        N, M, L = X.shape
        Y = self._propagate(X.reshape(N * M, L), np.repeat(u, M, axis=0), dt).reshape(N, M, L)
        x = Y.mean(axis=1)
        dX, dY = X - self.x[:, None], Y - x[:, None]
        cross = dX.transpose(0, 2, 1) @ dY / M
        try:
            self._transition = np.linalg.solve(self.P, cross).transpose(0, 2, 1)
        except np.linalg.LinAlgError:  # a state known exactly (zero variance)
            self._transition = (np.linalg.pinv(self.P, hermitian=True) @ cross).transpose(0, 2, 1)
        self.x = x
        self.P = self._add_process_noise(dY.transpose(0, 2, 1) @ dY / M, dt)
        return self.x

    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        y, valid = check_measurement(y, mask, self.measurement_names, self.batch_size)
        X = _sigma_points(self.x, self.P)
        N, M, L = X.shape
        rows = X.reshape(N * M, L)[:, :self._n]
        Y = (rows @ self._H[:, :self._n].T if self._H is not None else self.h(rows))
        Y = Y.reshape(N, M, -1)
        y_hat = Y.mean(axis=1)
        dY = Y - y_hat[:, None]
        if self.angular.size:  # spreads of a wrapped channel about its mean, not across +-pi
            dY[:, :, self.angular] = _wrap(dY[:, :, self.angular])
        dY = dY * valid[:, None, :]  # missing channels: no correlation, unit noise: zero gain
        dX = X - self.x[:, None]
        S = dY.transpose(0, 2, 1) @ dY / M + self._masked_noise(valid)
        cross = dX.transpose(0, 2, 1) @ dY / M
        e = self._innovation(y, y_hat, valid)
        K, S_inv_e = self._gain(cross, S, e)
        self.x = self.x + (K @ e[:, :, None])[:, :, 0]
        P = self.P - K @ S @ K.transpose(0, 2, 1)
        self.P = (P + P.transpose(0, 2, 1)) * 0.5
        self._record_update(e, S, S_inv_e, valid)
        return self.x, self.P


def _sigma_points(x: FloatArray, P: FloatArray) -> FloatArray:
    """``x +- sqrt(L) S`` columns, ``S S' = P`` (Cholesky; an eigen-decomposition with negative
    eigenvalues clipped if P lost definiteness): ``(N, 2 L, L)``."""
    L = x.shape[1]
    try:
        root = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(P)
        root = V * np.sqrt(np.maximum(w, 0.0))[:, None, :]
    spread = math.sqrt(L) * root.transpose(0, 2, 1)  # rows: the columns of the root
    return np.concatenate([x[:, None] + spread, x[:, None] - spread], axis=1)
