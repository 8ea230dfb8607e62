"""The compiled predict and update of :class:`~estimators.ekf.ExtendedKalmanFilter` for a model
with compiled equations (:mod:`marine_envs.compiled`): every filter of a batch in one call.

The same filter as the numpy path of :mod:`estimators.ekf` (the reference), without the work
that path spends on structure it does not see:

* the state Jacobian by the same central differences, of the model's compiled equations one
  filter at a time (no batch of ``2 n N`` points through numpy);
* the parameters' Jacobian as the model declares it (:mod:`estimators.ekf.dynamics`);
* the model rows ``[Phi_x, Gamma]`` of the transition from a degree-16 Taylor polynomial
  evaluated by Paterson-Stockmeyer (6 products of ``n x n`` matrices and one of ``n x (n + p)``
  instead of 7 of ``n x (n + p)``), scaled by a sharper norm: on the EKF benchmark's record no
  squaring where the numpy path takes 5 (:func:`transition_rows`);
* the update with ``H`` a selection of states: ``C = P H'`` is columns of ``P``, ``H P H'``
  entries of it, the gain from the Cholesky factor of ``H P H' + R``, and the covariance
  ``P - W W'``, the Joseph form's to rounding, or the Joseph form itself where that rounding
  would matter (:func:`update`);
* one symmetric half of each covariance computed, the other mirrored.

The dynamics a kernel integrates and differences are the model's own compiled equations
``core(x, u, d, q, out)``; estimated parameters enter through the packed constants ``q``, which
the kernel sets for each filter (:class:`~estimators.ekf.dynamics.CompiledDynamics`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from marine_envs.compiled import compile_for, jit

from .dynamics import CompiledDynamics

FloatArray = NDArray[np.float64]
#: Degree of the Taylor polynomial of the transition, and the largest ``alpha`` (see
#: :func:`transition_rows`) it is used at: beyond it the step is halved and the result squared.
#: Truncation ``<= 1.2**16 / 17! = 5e-14`` times ``|A dt|`` (the numpy path: ``1e-11``).
ORDER, NORM = 16, 1.2
#: ... and the largest maximum row sum of ``|A dt|`` (the terms of the polynomial sum to at most
#: ``exp(BOUND)`` times their rounding: 150 eps).
BOUND = 5.0
#: Coefficients of ``g(X) = sum_k X**k / (k + 1)!``, ``k < ORDER``: ``exp(X) = I + g(X) X``.
_G = tuple(1.0 / math.factorial(k + 1) for k in range(ORDER))
#: The update's short form ``P - W W'`` is used while every variance stays at least this share
#: of its prior: its rounding, ``~eps`` of the prior, is then below ``1e-12`` of the result.
SHORT_FORM = 1e-4

# -- the kernels ---------------------------------------------------------------------------------
class CompiledFilter:
    """The compiled path of an :class:`~estimators.ekf.ExtendedKalmanFilter` whose measurement
    is a selection of its model states.

    :param dynamics: the filter's dynamics (:func:`~estimators.ekf.dynamics.compiled_dynamics`).
    :param measured: the state measured by each channel ``(m,)``.
    :param n_d: number of disturbance channels.
    """

    def __init__(self, dynamics: CompiledDynamics, measured: Sequence[int], n_d: int) -> None:
        self.dynamics = dynamics
        self.measured = np.array(measured, dtype=np.intp)
        self._n_d = n_d
        self._q = dynamics.constants.copy()  # the kernel writes each filter's constants there
        self._predict = predict_kernel(dynamics.f, dynamics.integrate, dynamics.prepare,
                                       dynamics.parameter_jacobian, dynamics.n, dynamics.p)

    def predict(self, x: FloatArray, P: FloatArray, u: FloatArray, d: FloatArray, dt: float,
                substeps: int, Q: FloatArray, noise: FloatArray
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Estimates ``(N, n + p)`` and covariances after ``dt`` s (``substeps`` RK4 steps) with
        inputs ``u`` and disturbances ``d`` held, and the transitions' model rows
        ``(N, n, n + p)``; ``Q`` the model states' process noise over ``dt`` (symmetric),
        ``noise`` the parameters' variance added."""
        x, P, d = self._checked(x, P), _c(P), _c(d)
        N, size = x.shape
        if d.shape != (N, self._n_d):
            raise ValueError(f"disturbance has shape {d.shape}; expected ({N}, {self._n_d})")
        x_out, P_out = np.empty_like(x), np.empty_like(P)
        T = np.empty((N, self.dynamics.n, size))
        self._predict(x, P, _c(u), d, self._q, self.dynamics.table, dt / substeps,
                      substeps, dt, _c(Q), _c(noise), x_out, P_out, T)
        return x_out, P_out, T

    def compile(self, m: int, n_u: int) -> None:
        """Compile the kernels for ``m`` channels and ``n_u`` inputs now (loaded from the
        disk cache when it holds them), as the first prediction and update would."""
        size, n = self.dynamics.n + self.dynamics.p, self.dynamics.n
        x, P = np.zeros((1, size)), np.zeros((1, size, size))
        compile_for(self._predict, x, P, np.zeros((1, n_u)), np.zeros((1, self._n_d)),
                    self._q, self.dynamics.table, 0.1, 1, 0.1, np.zeros((n, n)),
                    np.zeros(self.dynamics.p), x, P, np.zeros((1, n, size)))
        e, S = np.zeros((1, m)), np.zeros((1, m, m))
        compile_for(update, x, P, e, np.ones((1, m), dtype=np.bool_), self.measured,
                    np.eye(m), x, P, S, np.zeros(1), np.ones(1, dtype=np.bool_))

    def update(self, x: FloatArray, P: FloatArray, e: FloatArray, valid: NDArray[np.bool_],
               R: FloatArray
               ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
        """Estimates and covariances after the innovations ``e`` ``(N, m)`` (0 where missing)
        of the ``valid`` channels with measurement noise ``R`` ``(m, m)``; the innovation
        covariances ``(N, m, m)``, ``e' S^-1 e`` and whether each filter's update was made and
        is finite (:func:`update`)."""
        x, P = self._checked(x, P), _c(P)
        N, m = e.shape
        x_out, P_out = np.empty_like(x), np.empty_like(P)
        S, nis, healthy = np.empty((N, m, m)), np.empty(N), np.empty(N, dtype=np.bool_)
        update(x, P, _c(e), np.ascontiguousarray(valid, dtype=np.bool_), self.measured, _c(R),
               x_out, P_out, S, nis, healthy)
        return x_out, P_out, S, nis, healthy

    def _checked(self, x: FloatArray, P: FloatArray) -> FloatArray:
        """``x`` as the kernels read it, once ``x`` and ``P`` are seen to have the shapes they
        index without bounds checks."""
        x = _c(x)
        size = self.dynamics.n + self.dynamics.p
        if x.ndim != 2 or x.shape[1] != size or np.shape(P) != (x.shape[0], size, size):
            raise ValueError(f"x has shape {x.shape} and P {np.shape(P)}; expected (N, {size}) "
                             f"and (N, {size}, {size})")
        return x


def _c(a: NDArray) -> FloatArray:
    """``a`` as a C-contiguous float array (the one layout compiled)."""
    return np.ascontiguousarray(a, dtype=float)


@functools.cache
def predict_kernel(f: Callable[..., None], integrate: Callable[..., None],
                   prepare: Callable[..., None], parameter_jacobian: Callable[..., None], n: int,
                   p: int) -> Callable[..., None]:
    """The compiled prediction of every filter of a batch for the dynamics of
    :class:`~estimators.ekf.dynamics.CompiledDynamics` with ``n`` states and ``p`` parameters
    (arguments: :meth:`CompiledFilter.predict`)."""
    size = n + p

    @jit
    def state_jacobian(x, u, d, q, A, moved, values):
        """``d f / d x`` into ``A[:, :n]``: central differences, steps ``1e-6 max(1, |x_i|)``
        (those of the numpy path)."""
        for i in range(n):
            moved[i] = x[i]
        for c in range(2 * n):  # one call site: the equations are merged in once
            i = c // 2
            step = 1e-6 * max(1.0, abs(x[i]))
            moved[i] = x[i] + step if c % 2 == 0 else x[i] - step
            f(moved, u, d, q, values[c % 2])
            moved[i] = x[i]
            if c % 2 == 1:
                for r in range(n):
                    A[r, i] = (values[0, r] - values[1, r]) / (2 * step)

    @jit
    def predict(Z, P, U, D, q, table, h, substeps, dt, Q, noise, Z_out, P_out, T_out):
        x, moved, values, work = np.empty(n), np.empty(n), np.empty((2, n)), np.empty((3, n))
        A, square, TP = np.empty((n, size)), np.empty((10, n, n)), np.empty((n, size))
        scaled, cross = np.empty((2, n, size)), np.empty((n, n))
        for b in range(Z.shape[0]):
            prepare(Z[b, n:], table, q)
            for i in range(n):
                x[i] = Z[b, i]
            state_jacobian(x, U[b], D[b], q, A, moved, values)
            parameter_jacobian(x, U[b], D[b], q, table, A)
            transition_rows(A, dt, T_out[b], square, scaled)
            integrate(x, U[b], D[b], q, h, substeps, moved, work)
            for i in range(n):
                Z_out[b, i] = moved[i]
            for j in range(n, size):
                Z_out[b, j] = Z[b, j]
            propagate(T_out[b], P[b], Q, noise, P_out[b], TP, cross)

    return predict


@jit
def _add_block(out, X, X2, X3, block):
    """``out += c_4i I + c_4i+1 X + c_4i+2 X^2 + c_4i+3 X^3`` for ``block = i`` (:data:`_G`)."""
    c0, c1, c2, c3 = _G[4 * block], _G[4 * block + 1], _G[4 * block + 2], _G[4 * block + 3]
    n = X.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] += c1 * X[i, j] + c2 * X2[i, j] + c3 * X3[i, j]
        out[i, i] += c0


@jit
def transition_rows(A, dt, T, square, scaled):
    """The model rows ``T = [Phi_x, Gamma]`` ``(n, n + p)`` of ``exp([[A_x, A_theta], [0, 0]]
    dt)`` for ``A = [A_x, A_theta]`` (one filter's ``d f / d z``).

    ``T = [I, 0] + g(X) M`` for ``M = [X, Y] = A dt / 2^s``, with ``g(X) = sum_k X^k / (k + 1)!``
    (:data:`ORDER` terms, Paterson-Stockmeyer: the powers ``X^2, X^3, X^4`` and a Horner scheme
    in ``X^4``), then ``s`` squarings ``T -> Phi_x T + [0, Gamma]``. ``s`` brings
    ``alpha = max(|X^3|^(1/3), |X^4|^(1/4))`` below :data:`NORM`: the truncation is at most
    ``sum_k>=16 alpha^k / (k + 1)!`` times ``|M|`` (Al-Mohy and Higham, SIAM J. Matrix Anal.
    Appl. 31, 2009, theorem 4.2; ``alpha`` is near the spectral radius, often far below
    ``|X|``). Scratch: ``square`` ``(10, n, n)``, ``scaled`` ``(2, n, n + p)``.
    """
    n, size = A.shape
    M, other = scaled[0], scaled[1]
    X, X2, X4, G, W, Phi = square[0], square[1], square[2], square[3], square[4], square[5]
    pair, powers = square[6:8].reshape(n, 2 * n), square[8:].reshape(n, 2 * n)
    for i in range(n):
        for j in range(size):
            M[i, j] = A[i, j] * dt
        for j in range(n):
            X[i, j] = M[i, j]
    np.dot(X, X, X2)
    for i in range(n):
        for j in range(n):
            pair[i, j], pair[i, n + j] = X[i, j], X2[i, j]
    np.dot(X2, pair, powers)  # [X^3, X^4]
    alpha = max(_norm(powers, 0, n) ** (1 / 3), _norm(powers, n, n) ** (1 / 4))
    # truncation: alpha below NORM; rounding: the terms' sum ~exp(|X|) kept below
    # exp(BOUND) (a non-normal X has alpha far below |X|)
    need = max(alpha / NORM, _norm(X, 0, n) / BOUND)
    squarings = 0
    if need > 1.0 and np.isfinite(need):  # not finite: so is T, which the update flags
        squarings = math.ceil(math.log2(need))
    s1 = 0.5**squarings  # the powers of A dt / 2^s: exact scalings by powers of two
    s2, s3, s4 = s1 * s1, s1 * s1 * s1, s1 * s1 * s1 * s1
    for i in range(n):
        if squarings > 0:
            for j in range(size):
                M[i, j] *= s1
            for j in range(n):
                X[i, j] *= s1
                X2[i, j] *= s2
                powers[i, j] *= s3
        for j in range(n):
            X4[i, j] = powers[i, n + j] * s4
    X3 = powers[:, :n]
    G[:, :] = 0.0
    blocks = ORDER // 4
    _add_block(G, X, X2, X3, blocks - 1)
    for block in range(blocks - 2, -1, -1):  # G = X^4 G + B_block
        np.dot(X4, G, W)
        G, W = W, G
        _add_block(G, X, X2, X3, block)
    np.dot(G, M, T)
    for i in range(n):
        T[i, i] += 1.0
    for _ in range(squarings):  # [Phi, Gamma] -> [Phi Phi, Phi Gamma + Gamma]
        for i in range(n):
            for j in range(n):
                Phi[i, j] = T[i, j]
        np.dot(Phi, T, other)
        for i in range(n):
            for j in range(n):
                T[i, j] = other[i, j]
            for j in range(n, size):
                T[i, j] += other[i, j]


@jit
def _norm(X, first, n):
    """The maximum row sum of ``|X[:, first:first + n]|``."""
    norm = 0.0
    for i in range(X.shape[0]):
        total = 0.0
        for j in range(first, first + n):
            total += abs(X[i, j])
        norm = max(norm, total)
    return norm


@jit
def propagate(T, P, Q, noise, out, TP, cross):
    """``out = Phi P Phi' + diag(Q, noise)`` for ``Phi = [[T], [0, I]]``: the lower half of
    ``(T P) T'`` and ``T P`` beside it, the parameters' block as it was (symmetric halves
    averaged, as the numpy path), each mirrored. ``Q`` symmetric."""
    n, size = T.shape
    np.dot(T, P, TP)
    np.dot(TP, T.T, cross)
    for i in range(n):
        for j in range(i + 1):
            value = cross[i, j] + Q[i, j]
            out[i, j] = value
            out[j, i] = value
        for j in range(n, size):
            out[i, j] = TP[i, j]
            out[j, i] = TP[i, j]
    for i in range(n, size):
        for j in range(n, i + 1):
            value = (P[i, j] + P[j, i]) * 0.5
            out[i, j] = value
            out[j, i] = value
        out[i, i] += noise[i - n]


@jit
def update(Z, P, E, valid, idx, R, Z_out, P_out, S_out, nis, healthy):
    """Every filter's update with the measurement ``y = z[idx] + v``, ``v ~ N(0, R)``.

    With ``C = P H'`` (columns of ``P``), ``S = H P H' + R = L L'`` (entries of ``P``; over the
    valid channels), ``W = C L^-T`` and ``v = L^-1 e``: the gain is ``K = W L^-1``,
    ``z += W v``, ``e' S^-1 e = v' v`` and the covariance ``P - W W'``, which is the Joseph form
    ``(I - K H) P (I - K H)' + K R K'`` of this gain to the rounding of the subtraction,
    ``~eps P_ii`` per variance. Where a variance falls below :data:`SHORT_FORM` of its prior
    that rounding would matter (a state measured far more precisely than it was known would
    lose its small variance) and the Joseph form itself is computed (:func:`_joseph`). One
    symmetric half is computed, the other mirrored.

    :param Z, P: estimates ``(N, n + p)`` and covariances before; ``Z_out, P_out`` after.
    :param E: innovations ``(N, m)`` (0 where missing); ``valid`` ``(N, m)`` the channels there.
    :param S_out: innovation covariances ``(N, m, m)`` (a missing channel: a unit row).
    :param nis: ``e' S^-1 e`` per filter; ``healthy``: the update was made (``S`` positive
        definite) and its result is finite with no negative variance.
    """
    N, size = Z.shape
    m = E.shape[1]
    channels = np.empty(m, dtype=np.intp)
    L, v = np.empty((m, m)), np.empty(m)
    # over the valid channels: rows W', C', K', columns M H' and K R, R; two (size, size)
    Wt, Ct, Kt = np.empty(m * size), np.empty(m * size), np.empty(m * size)
    MH, KR, R_valid = np.empty(size * m), np.empty(size * m), np.empty(m * m)
    first, second = np.empty((size, size)), np.empty((size, size))
    for b in range(N):
        count = 0
        for a in range(m):
            if valid[b, a]:
                channels[count] = a
                count += 1
            for c in range(m):
                both = valid[b, a] and valid[b, c]
                S_out[b, a, c] = P[b, idx[a], idx[c]] + R[a, c] if both else \
                    (1.0 if a == c else 0.0)
        if not _cholesky(S_out[b], channels, count, L):
            Z_out[b] = Z[b]
            P_out[b] = P[b]
            nis[b] = np.nan
            healthy[b] = False
            continue
        W, C = Wt[:count * size].reshape(count, size), Ct[:count * size].reshape(count, size)
        for a in range(count):  # W' = L^-1 C', v = L^-1 e
            column = idx[channels[a]]
            for r in range(size):
                C[a, r] = P[b, r, column]
                W[a, r] = C[a, r]
            value = E[b, channels[a]]
            for k in range(a):
                factor = L[a, k]
                value -= factor * v[k]
                for r in range(size):
                    W[a, r] -= factor * W[k, r]
            v[a] = value / L[a, a]
            for r in range(size):
                W[a, r] /= L[a, a]
        total = 0.0
        for a in range(count):
            total += v[a] * v[a]
        nis[b] = total
        for r in range(size):
            value = Z[b, r]
            for a in range(count):
                value += W[a, r] * v[a]
            Z_out[b, r] = value
        ok = _finite(Z_out[b])
        if _downdate(P[b], W, first, P_out[b]):
            healthy[b] = ok
            continue
        K, R_v = Kt[:count * size].reshape(count, size), R_valid[:count * count].reshape(count,
                                                                                          count)
        for a in range(count - 1, -1, -1):  # K' = L^-T W'
            for c in range(count):
                R_v[a, c] = R[channels[a], channels[c]]
            for r in range(size):
                K[a, r] = W[a, r]
            for k in range(a + 1, count):
                factor = L[k, a]
                for r in range(size):
                    K[a, r] -= factor * K[k, r]
            for r in range(size):
                K[a, r] /= L[a, a]
        healthy[b] = ok and _joseph(P[b], K, C, R_v, idx[channels[:count]],
                                    MH[:size * count].reshape(size, count),
                                    KR[:size * count].reshape(size, count), first, second,
                                    P_out[b])


@jit
def _downdate(P, W, WW, out):
    """``out = P - W W'`` (rows ``W'``; ``WW`` scratch) from the lower halves, ``P``'s two halves
    averaged (as the numpy path's symmetrisation), mirrored; True when finite with every variance
    at least :data:`SHORT_FORM` of its prior (else ``out`` is to be computed otherwise)."""
    np.dot(W.T, W, WW)
    ok = True
    for i in range(P.shape[0]):
        for j in range(i + 1):
            value = (P[i, j] + P[j, i]) * 0.5 - WW[i, j]
            out[i, j] = value
            out[j, i] = value
            ok = ok and np.isfinite(value)
        ok = ok and out[i, i] >= SHORT_FORM * P[i, i]
    return ok


@jit
def _joseph(P, K, C, R, measured, MH, KR, first, second, out):
    """``out = M - (M H' - K R) K'`` for ``M = P - K C'`` (rows ``K'``, ``C'``; ``H`` the
    selection of the states ``measured``): the Joseph form ``M (I - K H)' + K R K'``, its two
    halves averaged (as the numpy path's symmetrisation); True when finite with no negative
    variance. Scratch: ``MH``, ``KR`` ``(n, count)``, ``first``, ``second`` ``(n, n)``."""
    size, count = P.shape[0], K.shape[0]
    np.dot(K.T, C, first)
    np.dot(K.T, R, KR)
    for i in range(size):  # M, and M H' - K R
        for j in range(size):
            first[i, j] = P[i, j] - first[i, j]
        for a in range(count):
            MH[i, a] = first[i, measured[a]] - KR[i, a]
    np.dot(MH, K, second)
    ok = True
    for i in range(size):
        for j in range(i + 1):
            value = (first[i, j] - second[i, j] + first[j, i] - second[j, i]) * 0.5
            out[i, j] = value
            out[j, i] = value
            ok = ok and np.isfinite(value)
        ok = ok and out[i, i] >= 0.0
    return ok


@jit
def _cholesky(S, channels, count, L):
    """``L L' = S`` over the ``count`` rows and columns ``channels``; False unless positive
    definite."""
    for a in range(count):
        for c in range(a + 1):
            total = S[channels[a], channels[c]]
            for k in range(c):
                total -= L[a, k] * L[c, k]
            if a == c:
                if not total > 0.0:  # also NaN
                    return False
                L[a, a] = math.sqrt(total)
            else:
                L[a, c] = total / L[c, c]
    return True


@jit
def _finite(v):
    """True when no entry of the 1-D array ``v`` is NaN or inf."""
    for i in range(v.size):
        if not np.isfinite(v[i]):
            return False
    return True
