"""What an offline run of the extended Kalman filter gives
(:class:`~estimators.ekf.FilterResult`), and the Rauch-Tung-Striebel smoother over it
(:func:`~estimators.ekf.rts_smooth`)."""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from marine_envs.compiled import jit

FloatArray = NDArray[np.float64]


@dataclasses.dataclass
class FilterResult:
    """An offline filter run over ``T`` steps of ``N`` filters (augmented state of size ``n``).

    :param x, P: filtered estimates ``(T, N, n)`` and covariances ``(T, N, n, n)`` (after the
        update with measurement ``k``).
    :param x_pred, P_pred: predictions for step ``k`` (``x_pred[0]`` is the initial estimate).
    :param transition: ``Phi_k`` ``(T - 1, N, n, n)`` from step ``k`` to ``k + 1``.
    :param innovation: ``(T, N, m)``, 0 where a channel was missing.
    :param nis, dof: normalised innovation squared ``(T, N)`` and its degrees of freedom.
    :param state_names: names of the ``n`` states.
    """

    x: FloatArray
    P: FloatArray
    x_pred: FloatArray
    P_pred: FloatArray
    transition: FloatArray
    innovation: FloatArray
    nis: FloatArray
    dof: NDArray[np.intp]
    state_names: tuple[str, ...]

    @property
    def std(self) -> FloatArray:
        """Standard deviation of each state, ``(T, N, n)``."""
        return np.sqrt(np.maximum(np.diagonal(self.P, axis1=-2, axis2=-1), 0.0))


@dataclasses.dataclass
class SmootherResult:
    """Rauch-Tung-Striebel smoothed estimates ``x`` ``(T, N, n)`` and covariances ``P``
    ``(T, N, n, n)``, with the forward run they were computed from."""

    x: FloatArray
    P: FloatArray
    filtered: FilterResult

    @property
    def std(self) -> FloatArray:
        """Standard deviation of each state, ``(T, N, n)``."""
        return np.sqrt(np.maximum(np.diagonal(self.P, axis1=-2, axis2=-1), 0.0))


def rts_smooth(result: FilterResult) -> SmootherResult:
    """Rauch-Tung-Striebel smoothing of a forward run: ``C_k = P_k Phi_k' P_pred_{k+1}^-1``,
    ``x_s,k = x_k + C_k (x_s,k+1 - x_pred,k+1)``, ``P_s,k = P_k + C_k (P_s,k+1 - P_pred,k+1) C_k'``;
    compiled (:func:`~estimators.ekf.smoother.rts_loop`) for a finite run, the numpy loop below
    (the reference) otherwise.
    """
    arrays = (result.x, result.P, result.x_pred, result.P_pred, result.transition)
    if all(np.isfinite(a).all() for a in arrays):  # (else numpy's NaNs, not numba's error)
        x, P = np.empty_like(result.x), np.empty_like(result.P)
        rts_loop(*(np.ascontiguousarray(a) for a in arrays), x, P)
        return SmootherResult(x, P, result)
    x, P = result.x.copy(), result.P.copy()
    for k in range(x.shape[0] - 2, -1, -1):
        # C' = P_pred^-1 Phi P (P and P_pred symmetric)
        Ct = np.linalg.solve(result.P_pred[k + 1], result.transition[k] @ result.P[k])
        C = Ct.transpose(0, 2, 1)
        x[k] = result.x[k] + (C @ (x[k + 1] - result.x_pred[k + 1])[:, :, None])[:, :, 0]
        Pk = result.P[k] + C @ (P[k + 1] - result.P_pred[k + 1]) @ Ct
        P[k] = (Pk + Pk.transpose(0, 2, 1)) * 0.5
    return SmootherResult(x, P, result)


@jit
def rts_loop(x, P, x_pred, P_pred, transition, x_out, P_out):
    """The Rauch-Tung-Striebel recursion of :func:`~estimators.ekf.rts_smooth` over a finite
    forward run of ``N`` filters (``x`` ``(T, N, n)``, ``P`` ``(T, N, n, n)``, ...), written to
    ``x_out`` and ``P_out``: the same solve and products, without a Python step per sample."""
    T, N, n = x.shape
    x_out[T - 1] = x[T - 1]
    P_out[T - 1] = P[T - 1]
    for k in range(T - 2, -1, -1):
        for b in range(N):
            Ct = np.linalg.solve(P_pred[k + 1, b], np.dot(transition[k, b], P[k, b]))
            C = np.ascontiguousarray(Ct.T)
            x_out[k, b] = x[k, b] + np.dot(C, x_out[k + 1, b] - x_pred[k + 1, b])
            Pk = P[k, b] + np.dot(np.dot(C, P_out[k + 1, b] - P_pred[k + 1, b]), Ct)
            P_out[k, b] = (Pk + Pk.T) * 0.5
