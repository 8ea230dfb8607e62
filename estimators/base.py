"""The estimator contract (docs/architecture.md contract 3), shared by every filter and observer.

An estimator holds a batch of ``N`` independent filters (leading axis), so one object serves a
vector environment. A step is ``predict(u)`` with the input applied over the last control period,
then ``update(y, mask)`` with the measurement taken at its end. States, inputs and measurements are
in the vehicle model's units (SI, radians), absolute (not deviations from a trim).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.floating]


class Estimator(ABC):
    """A batch of state estimators with a common model.

    Attributes, all with the batch on the leading axis and updated in place by each call:

    * ``x`` ``(N, n)``: the current estimate;
    * ``P`` ``(N, n, n)``: its covariance (NaN for observers that have none);
    * ``innovation`` ``(N, m)``: the last measurement minus its prediction (0 where masked);
    * ``diverged`` ``(N,)``: the filter has been judged divergent (see each class).
    """

    #: Names of the estimated states, in order (the model's, plus any appended parameters).
    state_names: tuple[str, ...]
    #: Names of the measured channels ``y`` expects, in order.
    measurement_names: tuple[str, ...]
    #: Nominal time step of ``predict``, s.
    dt: float

    x: FloatArray
    P: FloatArray
    innovation: FloatArray
    diverged: NDArray[np.bool_]

    @property
    def batch_size(self) -> int:
        """Number of independent filters ``N``."""
        return self.x.shape[0]

    @abstractmethod
    def bind(self, batch_size: int) -> None:
        """Allocate ``batch_size`` filters (their state is undefined until :meth:`reset`)."""

    @abstractmethod
    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        """(Re)start filters ``idx`` (all if None) from ``x0`` ``(n,)`` or ``(len(idx), n)`` and
        covariance ``P0`` ``(n, n)``; None = the estimator's defaults."""

    @abstractmethod
    def predict(self, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """Propagate over ``dt`` (default: :attr:`dt`) s with input ``u`` ``(N, n_u)`` held;
        returns ``x``."""

    @abstractmethod
    def update(self, y: ArrayLike, mask: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """Correct with measurement ``y`` ``(N, m)``; ``mask`` ``(N, m)`` marks the valid channels
        (non-finite values of ``y`` count as missing too). Returns ``(x, P)``."""


def as_batch(name: str, value: ArrayLike, batch_size: int, width: int) -> NDArray[np.float64]:
    """``value`` as an ``(N, width)`` float array (a single row is broadcast), or a ValueError that
    names the argument and the shape expected."""
    a = np.asarray(value, dtype=float)
    if a.ndim == 1 and a.shape == (width,):
        return np.broadcast_to(a, (batch_size, width))
    if a.shape != (batch_size, width):
        raise ValueError(f"{name} has shape {a.shape}; expected ({batch_size}, {width}) or "
                         f"({width},)")
    return a


def check_covariance(name: str, value: ArrayLike, n: int) -> NDArray[np.float64]:
    """A symmetric positive semi-definite ``(n, n)`` matrix, or a ValueError naming ``name``.

    A vector is taken as the diagonal.
    """
    a = np.asarray(value, dtype=float)
    if a.ndim == 1:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"{name} has shape {a.shape}; expected ({n}, {n}) or ({n},)")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} has non-finite entries")
    if not np.allclose(a, a.T, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(a).max())):
        raise ValueError(f"{name} is not symmetric")
    lowest = np.linalg.eigvalsh(a).min()
    if lowest < -1e-10 * max(1.0, np.abs(a).max()):
        raise ValueError(f"{name} is not positive semi-definite (smallest eigenvalue {lowest:.3g})")
    return a


def check_measurement(y: ArrayLike, mask: ArrayLike | None, names: tuple[str, ...],
                      batch_size: int, dtype: type | np.dtype = np.float64
                      ) -> tuple[NDArray[np.floating], NDArray[np.bool_]]:
    """``y`` as an ``(N, m)`` array of the channels ``names``, and which entries are valid
    (finite and masked in); a ValueError names the shape expected."""
    N, m = batch_size, len(names)
    y = np.asarray(y, dtype=dtype)
    if y.shape != (N, m):
        raise ValueError(f"y has shape {y.shape}; expected ({N}, {m}): {', '.join(names)}")
    valid = np.isfinite(y)
    if mask is not None:
        valid &= as_batch("mask", mask, N, m).astype(bool)
    return y, valid
