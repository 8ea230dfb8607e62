"""The Kalman filter's step, compiled: written once, for one filter at a time or for filters
that share one covariance (:class:`~estimators.kalman.KalmanFilter`'s only arithmetic).

A filter at a time, with the matrix sizes fixed at compile time: the loops are unrolled and the
scratch matrices live on the stack, so a covariance per filter costs what its arithmetic costs
(numpy's batched small-matrix calls cost more in overhead than in arithmetic). Sums are in
float64 also for float32 filters. Missing channels get zero rows of ``H`` and unit noise (hence
zero gain), the update is in Joseph form, and each covariance is computed once per pair
``(i, j)``, so it is exactly symmetric.

Filters that share one covariance (``P`` of shape ``(1, n, n)``: started alike and measured
alike) take the same steps with the covariance's part done once: one prediction of ``P``, one
innovation covariance, one gain and one Joseph update serve the batch, and each filter adds its
own estimate, innovation and statistic. The numbers are those of the per-filter step.

These kernels replaced a batched numpy twin (commit b31a8e0); the numbers that twin gave are kept
as recorded data (``tests/data/kalman_reference.npz``), which the kernels are tested against.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import cache
from typing import NamedTuple

import numpy as np

from marine_envs.compiled import jit, local_array


class Kernels(NamedTuple):
    """The compiled steps of filters of ``n`` states and ``m`` channels.

    ``predict(F, G, c, Qs, second, x, u, P, x_out, P_out)``: ``x_out = F x + G u + c`` per
    filter and ``P_out = F P F' + Q`` per covariance (``P`` ``(N, n, n)`` or shared
    ``(1, n, n)``), ``Q = Qs[1]`` where ``second`` (of the covariance's filter) else ``Qs[0]``.

    ``update(H, R, d, wrapped, x, P, y, valid, x_out, P_out, e, S, nis, dof, finite)``: the
    Joseph-form update with the ``valid`` channels of ``y`` (every channel valid when ``P`` is
    shared), the innovation (0 where missing; wrapped to (-pi, pi] where ``wrapped``), its
    covariance (one per covariance), its normalised square, the number of channels used and
    whether ``x_out`` and ``P_out`` are finite, per filter.
    """

    predict: Callable[..., None]
    update: Callable[..., None]


@cache
def kernels(n: int, m: int) -> Kernels:
    """The kernels of ``n`` states and ``m`` channels (compiled on first use, cached on disk)."""
    nn, nm, mm = n * n, n * m, m * m
    # the compiled functions they call are closure cells, not globals: the disk cache's key
    # visits a function's globals in the order of a set of names, which changes from process to
    # process (a miss each time) once there are two; closure cells have a fixed order
    stack, predict_state, predict_covariance = local_array, _predict_state, _predict_covariance
    model, covariance, cholesky, whitened = (_masked_model, _innovation_covariance, _cholesky,
                                             _whitened_square)
    gain, corrected, joseph = _gain, _corrected, _joseph

    @jit
    def predict(F, G, c, Qs, second, x, u, P, x_out, P_out):
        FP = stack(nn)
        switching = Qs.shape[0] > 1
        shared = P.shape[0] == 1
        for b in range(x.shape[0]):
            predict_state(F, G, c, x[b], u[b], x_out[b], n)
            if b == 0 or not shared:
                Q = Qs[1] if switching and second[b] else Qs[0]
                predict_covariance(F, Q, P[b], P_out[b], FP, n)

    @jit
    def update(H, R, d, wrapped, x, P, y, valid, x_out, P_out, e, S, nis, dof, finite):
        Hm, Rm, U, L = stack(nm), stack(mm), stack(nm), stack(mm)
        K, KR, A, AP = stack(nm), stack(nm), stack(nn), stack(nn)
        inv, z = stack(m), stack(m)
        shared = P.shape[0] == 1
        settled = True  # the (shared) covariance's update is finite
        for b in range(x.shape[0]):
            dof[b] = model(H, R, d, wrapped, x[b], y[b], valid[b], e[b], Hm, Rm, n, m)
            if b == 0 or not shared:
                covariance(P[b], Hm, Rm, U, L, S[b], n, m)
                cholesky(L, inv, m)
            nis[b] = whitened(e[b], L, inv, z, m)
            if b == 0 or not shared:
                gain(U, L, inv, K, n, m)
            finite[b] = corrected(x[b], K, e[b], x_out[b], n, m)
            if b == 0 or not shared:
                settled = joseph(P[b], Hm, Rm, K, A, AP, KR, P_out[b], n, m)
            finite[b] = finite[b] & settled

    return Kernels(predict, update)


@jit
def _predict_state(F, G, c, x, u, x_out, n):
    """One filter's predicted estimate ``x_out = F x + G u + c``."""
    for i in range(n):
        t = c[i]
        for k in range(n):
            t += F[i, k] * x[k]
        for k in range(u.size):
            t += G[i, k] * u[k]
        x_out[i] = t


@jit
def _predict_covariance(F, Q, P, P_out, FP, n):
    """One predicted covariance ``P_out = F P F' + Q`` (``FP``: scratch of ``n * n``)."""
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


@jit
def follow_innovations(nis, dof, nis_mean, weight, limit, finite, bad):
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
