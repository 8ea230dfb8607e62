"""The patent's standard form of a plant and its augmented descriptor system (docs/models.md
1.3, 1.5): :func:`standard_form`, :func:`usv_standard_form`, :func:`augment`."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from marine_envs.models.usv import USVModel

from ..base import FloatArray


# -- 1. standard form --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)  # arrays: compare fields explicitly
class StandardForm:
    """A plant ``x_c' = A_c x_c + B_c u + D_c d``, ``y_c = C_c x_c`` and its standard form.

    ``x = T x_c = [x1; x2]`` (``x1``: the ``n1`` states the disturbance enters, measured
    directly), ``y = S y_c = [y1; y2]`` with ``y1 = x1``. Then ``A = T A_c T^-1``, ``B = T B_c``,
    ``D = T D_c = [D1; 0]``, ``C = S C_c T^-1 = [C1; C2]`` with ``C1 = [I 0]``; ``C2`` is the full
    width ``(p - n1, n)`` block (``C2full`` of docs/models.md 1.3).
    """

    A_c: FloatArray
    B_c: FloatArray
    D_c: FloatArray
    C_c: FloatArray
    T: FloatArray
    S: FloatArray
    A: FloatArray
    B: FloatArray
    D: FloatArray
    C: FloatArray
    C1: FloatArray
    C2: FloatArray
    D1: FloatArray
    n1: int
    state_names: tuple[str, ...]  #: original state order (of ``x_c``)
    measurement_names: tuple[str, ...]  #: original channel order (of ``y_c``)

    @property
    def standard_state_names(self) -> tuple[str, ...]:
        """Names of ``x = T x_c``."""
        return tuple(self.state_names[int(np.argmax(row))] for row in np.abs(self.T))


def standard_form(A_c: ArrayLike, B_c: ArrayLike, D_c: ArrayLike, C_c: ArrayLike,
                  state_names: Sequence[str] | None = None,
                  measurement_names: Sequence[str] | None = None) -> StandardForm:
    """Reorder states and channels into the patent's standard form (permutations ``T``, ``S``).

    :param A_c: ``(n, n)`` state matrix, 1/s.
    :param B_c: ``(n, n_u)`` input matrix.
    :param D_c: ``(n, n1)`` disturbance matrix; it must enter exactly ``n1`` states.
    :param C_c: ``(p, n)`` output matrix whose rows are rows of the identity; every state
        ``D_c`` enters must be measured.
    :raises ValueError: the plant cannot be put into the standard form, saying why.
    """
    A_c, B_c, D_c, C_c = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A_c, B_c, D_c, C_c))
    n, n1 = A_c.shape[0], D_c.shape[1]
    if A_c.shape != (n, n) or B_c.shape[0] != n or D_c.shape[0] != n or C_c.shape[1] != n:
        raise ValueError(f"shapes A_c {A_c.shape}, B_c {B_c.shape}, D_c {D_c.shape}, C_c "
                         f"{C_c.shape} do not fit together (B_c and D_c need n rows)")
    names = tuple(state_names or [f"x{i}" for i in range(n)])
    channels = tuple(measurement_names or [f"y{i}" for i in range(C_c.shape[0])])
    hit = [int(i) for i in np.flatnonzero(np.abs(D_c).sum(axis=1))]
    if len(hit) != n1:
        raise ValueError(f"D_c enters {len(hit)} states but has {n1} columns; the standard form "
                         "needs D1 square and invertible")
    if not all(np.count_nonzero(row) == 1 and row.max() == 1 for row in C_c):
        raise ValueError("C_c rows must be rows of the identity (each channel measures one state)")
    selected = [int(np.argmax(row)) for row in C_c]
    missing = [names[i] for i in hit if i not in selected]
    if missing:
        raise ValueError(f"states {missing} are hit by the disturbance but not measured; the "
                         "standard form needs y1 = x1")
    order = hit + [i for i in range(n) if i not in hit]
    y1 = [selected.index(i) for i in hit]
    T = np.eye(n)[order]
    S = np.eye(len(selected))[y1 + [j for j in range(len(selected)) if j not in y1]]
    C = S @ C_c @ T.T
    D = T @ D_c
    D1 = D[:n1]
    if abs(np.linalg.det(D1)) < 1e-12:
        raise ValueError("D1 is singular; the patent's method needs it invertible")
    return StandardForm(A_c=A_c, B_c=B_c, D_c=D_c, C_c=C_c, T=T, S=S, A=T @ A_c @ T.T,
                        B=T @ B_c, D=D, C=C, C1=C[:n1], C2=C[n1:], D1=D1, n1=n1,
                        state_names=names, measurement_names=channels)


def usv_standard_form(model: USVModel | None = None) -> StandardForm:
    """Standard form (docs/models.md 1.3) of ``model`` (default: the USV observer patent's):
    ``x = [r, p, v, psi, phi]``, ``y = [r, p, psi, phi]``, ``D1 = I2``. With
    ``wave_input="angle"`` (reading (b)) it is ``x = [psi, phi, v, r, p]``, ``y2 = [r, p]``, for
    which the LMI is infeasible."""
    model = USVModel() if model is None else model
    A_c, B_c, D_c = model.linearize()
    return standard_form(A_c, B_c, D_c, model.C, model.state_names, model.measured_names)


# -- 2. augmented descriptor system ------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class AugmentedSystem:
    """The augmented system ``E_bar x_bar' = A_bar x_bar + ...`` and ``M`` (docs/models.md 1.5).

    ``x_bar = [x; eps]`` (``n_bar = n + m2``); ``MA = M A_bar``, ``MD = M D_bar = E1' D1``,
    ``R = [0; I]``, ``Cbar2 = [C2, I]``.
    """

    E: FloatArray
    Abar: FloatArray
    Dbar: FloatArray
    Nbar: FloatArray
    Cbar2: FloatArray
    R: FloatArray
    M: FloatArray
    MA: FloatArray
    MD: FloatArray
    n1: int


def augment(A: ArrayLike, D: ArrayLike, C2: ArrayLike) -> AugmentedSystem:
    """The augmented descriptor system of a plant in standard form.

    :param A: ``(n, n)`` standard-form state matrix, 1/s.
    :param D: ``(n, n1)`` disturbance matrix ``[D1; 0]``.
    :param C2: ``(m2, n)`` rows of the quantized outputs ``y2`` (full width).
    :raises ValueError: shapes, or ``D``/``C2`` not in standard form.
    """
    A, D, C2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (A, D, C2))
    n, n1, m2 = A.shape[0], D.shape[1], C2.shape[0]
    if A.shape != (n, n) or D.shape[0] != n or C2.shape[1] != n:
        raise ValueError(f"shapes A {A.shape}, D {D.shape}, C2 {C2.shape} do not fit together")
    if np.any(D[n1:]) or abs(np.linalg.det(D[:n1])) < 1e-12:
        raise ValueError("D must be [D1; 0] with D1 invertible (standard form)")
    if np.any(C2[:, :n1]):
        raise ValueError("C2 must not measure x1 (standard form: y1 = x1, y2 = C2 x2)")
    eye, zero = np.eye(m2), np.zeros
    E = np.block([[np.eye(n), zero((n, m2))], [zero((m2, n)), zero((m2, m2))]])
    Abar = np.block([[A, zero((n, m2))], [zero((m2, n)), -eye]])
    R = np.vstack([zero((n, m2)), eye])
    Cbar2 = np.hstack([C2, eye])
    M = np.linalg.inv(E + R @ Cbar2)
    Dbar = np.vstack([D, zero((m2, n1))])
    return AugmentedSystem(E=E, Abar=Abar, Dbar=Dbar, Nbar=R.copy(), Cbar2=Cbar2, R=R, M=M,
                           MA=M @ Abar, MD=M @ Dbar, n1=n1)
