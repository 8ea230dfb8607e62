"""Nomoto: first-order yaw model of a ship, a manoeuvring host for zig-zag tests
(docs/models.md section 7).

Nomoto's first-order steering model with a rudder offset::

    r_dot   = (K * (delta + delta0) - r) / T + w_r
    psi_dot = r

``x = [r, psi]`` (rad/s, rad), ``u = [delta]`` (rad), ``d = [w_r]`` (rad/s^2): a yaw moment per
unit inertia entering the r row. Sign convention of the zig-zag data (HSVA): a positive (port)
rudder gives a negative r, so the nominal gain K is negative. The rudder that holds a straight
course is ``-delta0`` (the nominal input :attr:`NomotoModel.u0`). The model has no environment;
the catalogue's damping forms on r add Norrbin's ``r**3`` and ``r*abs(r)`` terms.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require

#: Layout of the packed constants ``p`` of :func:`nomoto_rhs`.
GAIN, TIME_CONSTANT, OFFSET = range(3)


@jit
def nomoto_rhs(x, u, d, p, out):
    """One ship's ``x_dot`` (module docstring); ``p`` packed by :meth:`NomotoModel.pack`."""
    r = x[0]
    out[0] = (p[GAIN] * (u[0] + p[OFFSET]) - r) / p[TIME_CONSTANT] + d[0]
    out[1] = r


@dataclasses.dataclass(frozen=True)
class NomotoParams:
    """Parameters of the Nomoto model; names are docs/models.md's symbols. SI units, radians."""

    #: rudder-to-yaw-rate gain, 1/s; either sign, nonzero (< 0: port rudder turns to port)
    K: float = -0.08  # [PROPOSED: typical large tanker, model scale]
    #: yaw time constant, s; either sign, nonzero (< 0: a course-unstable ship, whose linear yaw
    #: motion diverges unless a nonlinear damping such as Norrbin's holds it)
    T: float = 10.0  # [PROPOSED: typical large tanker, model scale]
    #: rudder offset, rad: the rudder -delta0 holds a straight course
    delta0: float = 0.0  # [PROPOSED: symmetric ship, no offset]
    delta_max: float = math.radians(35.0)  #: rudder limit, rad  [PROPOSED: usual +-35 deg]

    def __post_init__(self) -> None:
        require(math.isfinite(self.delta_max) and self.delta_max > 0, "delta_max",
                self.delta_max, "must be finite and > 0")
        for name in ("K", "T"):
            value = getattr(self, name)
            require(math.isfinite(value) and value != 0, name, value, "must be finite and nonzero")
        require(math.isfinite(self.delta0), "delta0", self.delta0, "must be finite")


class NomotoModel(VehicleModel):
    """First-order Nomoto yaw model of a ship (Nomoto et al. 1957), with a rudder offset."""

    name: ClassVar[str] = "nomoto"
    state_names: ClassVar[tuple[str, ...]] = ("r", "psi")
    input_names: ClassVar[tuple[str, ...]] = ("delta",)
    disturbance_names: ClassVar[tuple[str, ...]] = ("w_r",)
    state_units: ClassVar[tuple[str, ...]] = ("rad/s", "rad")
    input_units: ClassVar[tuple[str, ...]] = ("rad",)
    disturbance_units: ClassVar[tuple[str, ...]] = ("rad/s^2",)
    #: A zig-zag test's channels: yaw rate (gyro) and heading (compass), both states.
    measured_names: ClassVar[tuple[str, ...]] = ("r", "psi")
    is_linear: ClassVar[bool] = True
    #: ``K * delta0 / T`` is affine in delta0 (K, T held).
    affine_parameters: ClassVar[frozenset[str]] = frozenset({"delta0"})
    #: ``rhs`` reads K, T, delta0 at call time with numpy arithmetic: one value per row works.
    row_parameters: ClassVar[bool] = True
    lag_parameters: ClassVar[tuple[str, str]] = ("K", "T")
    richer_models: ClassVar[tuple[str, ...]] = ("mmg",)
    equations: ClassVar[Equations] = Equations(nomoto_rhs)

    def __init__(self, params: NomotoParams | None = None) -> None:
        super().__init__(NomotoParams() if params is None else params)

    @property
    def u0(self) -> FloatArray:
        """The rudder that holds a straight course: ``[-delta0]``."""
        return np.array([-self.params.delta0])

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.array([-self.params.delta_max]), np.array([self.params.delta_max])

    def pack(self) -> FloatArray:
        k = self.params
        return np.stack(np.broadcast_arrays(k.K, k.T, k.delta0), axis=-1).astype(float)

    def linearize(self, x0: ArrayLike | None = None, u0: ArrayLike | None = None,
                  eps: float = 0.0, d0: ArrayLike | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Exact ``(A, B, E)``: the model is affine, so they do not depend on the point (the
        offset ``K * delta0 / T`` is ``rhs(x0, u0)``, which the exact step and
        :class:`~.base.LinearizedModel` take from :meth:`rhs`)."""
        k = self.params
        A = np.array([[-1 / k.T, 0.0], [1.0, 0.0]])
        B = np.array([[k.K / k.T], [0.0]])
        E = np.array([[1.0], [0.0]])
        return A, B, E

    @property
    def C(self) -> FloatArray:
        """Output matrix of the measured channels ``[r, psi]`` (= I2)."""
        return np.eye(2)[[self.state_names.index(n) for n in self.measured_names]]
