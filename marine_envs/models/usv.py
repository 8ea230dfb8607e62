"""USV: 5-state rudder-sway-yaw-roll model (the USV observer patent; docs/models.md section 1).

Van Amerongen / Van der Klugt rudder-roll structure with the patent's parameters::

    v_dot   = (-v + Kdv*delta) / Tv
    r_dot   = (Kvr*v - r + Kdr*delta) / Tr + w_psi
    psi_dot = r
    p_dot   = wn^2 * (Kvp*v + Kdp*delta) - 2*zeta*wn*p - wn^2*phi + w_phi
    phi_dot = p

``x = [v, r, psi, p, phi]`` (m/s, rad/s, rad, rad/s, rad), ``u = [delta]`` (rad),
``d = [w_psi, w_phi]`` (rad/s^2): wave yaw and roll moments per unit inertia entering the r and p
rows. That is reading (a) of docs/models.md 1.2, the only one for which the patent's observer is
feasible; reading (b), disturbances entering the psi and phi rows, is kept as
``wave_input="angle"`` for model-mismatch studies.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require

#: Layout of the packed constants ``p`` of :func:`usv_rhs`.
KVR, WN, ZETA, KDR, TR, TV, KDV, KVP, KDP, MOMENT = range(10)


@jit
def usv_rhs(x, u, d, p, out):
    """One boat's ``x_dot`` (module docstring); ``p`` packed by :meth:`USVModel.pack`."""
    v, r, p_roll, phi = x[0], x[1], x[3], x[4]
    delta = u[0]
    moment = p[MOMENT] != 0.0
    w_psi, w_phi = d[0], d[1]
    out[0] = (-v + p[KDV] * delta) / p[TV]
    out[1] = (p[KVR] * v - r + p[KDR] * delta) / p[TR] + (w_psi if moment else 0.0)
    out[2] = r + (0.0 if moment else w_psi)
    out[3] = p[WN] ** 2 * (p[KVP] * v + p[KDP] * delta - phi) \
        - 2 * p[ZETA] * p[WN] * p_roll + (w_phi if moment else 0.0)
    out[4] = p_roll + (0.0 if moment else w_phi)


@dataclasses.dataclass(frozen=True)
class USVParams:
    """Parameters of the USV model; names are docs/models.md's symbols. SI units, radians."""

    Kvr: float = -0.46  #: sway-to-yaw-rate gain, rad/s per m/s  [SEED]
    wn: float = 0.63  #: roll natural frequency, rad/s  [SEED]
    zeta: float = 0.0936  #: roll damping ratio, -  [SEED]
    Kdr: float = -0.0211  #: rudder-to-yaw-rate gain, rad/s per rad  [SEED]
    Tr: float = 1.6667  #: yaw time constant, s  [SEED]
    Tv: float = 10.0  #: sway time constant, s  [SEED]
    Kdv: float = 0.0780  #: rudder-to-sway gain, m/s per rad  [SEED]
    Kvp: float = 1.6380  #: sway-to-roll gain, rad per m/s  [SEED]
    Kdp: float = -0.0852  #: rudder-to-roll gain, rad per rad  [SEED]
    delta_max: float = math.radians(35.0)  #: rudder limit, rad  [PROPOSED: usual +-35 deg]
    wave_input: Literal["moment", "angle"] = "moment"  #: where w_psi, w_phi enter (see module doc)

    def __post_init__(self) -> None:
        for name in ("wn", "Tr", "Tv", "delta_max"):
            value = getattr(self, name)
            require(math.isfinite(value) and value > 0, name, value, "must be finite and > 0")
        require(math.isfinite(self.zeta) and self.zeta >= 0, "zeta", self.zeta,
                "must be finite and >= 0")
        for name in ("Kvr", "Kdr", "Kdv", "Kvp", "Kdp"):
            value = getattr(self, name)
            require(math.isfinite(value), name, value, "must be finite")
        require(self.wave_input in ("moment", "angle"), "wave_input", self.wave_input,
                "must be 'moment' or 'angle'")


class USVModel(VehicleModel):
    """Rudder-roll-yaw model of an unmanned surface vessel (the USV observer patent)."""

    name: ClassVar[str] = "usv"
    state_names: ClassVar[tuple[str, ...]] = ("v", "r", "psi", "p", "phi")
    input_names: ClassVar[tuple[str, ...]] = ("delta",)
    disturbance_names: ClassVar[tuple[str, ...]] = ("w_psi", "w_phi")
    state_units: ClassVar[tuple[str, ...]] = ("m/s", "rad/s", "rad", "rad/s", "rad")
    input_units: ClassVar[tuple[str, ...]] = ("rad",)
    disturbance_units: ClassVar[tuple[str, ...]] = ("rad/s^2", "rad/s^2")
    #: Both wave moments follow the transverse wave slope
    #: (:class:`~marine_envs.sea.USVWaveCoupling`): the yaw moment is a fixed multiple of the
    #: roll moment in any sea.
    wave_disturbances: ClassVar[tuple[str, ...]] = ("w_psi", "w_phi")
    #: The USV observer patent's measured channels: p = 4, sway speed v is not measured.
    measured_names: ClassVar[tuple[str, ...]] = ("r", "psi", "p", "phi")
    is_linear: ClassVar[bool] = True
    row_parameters: ClassVar[bool] = True
    equations: ClassVar[Equations] = Equations(usv_rhs)

    def __init__(self, params: USVParams | None = None) -> None:
        super().__init__(USVParams() if params is None else params)

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        return np.array([-self.params.delta_max]), np.array([self.params.delta_max])

    def pack(self) -> FloatArray:
        k = self.params
        moment = 1.0 if k.wave_input == "moment" else 0.0
        return np.stack(np.broadcast_arrays(k.Kvr, k.wn, k.zeta, k.Kdr, k.Tr, k.Tv, k.Kdv, k.Kvp,
                                            k.Kdp, moment), axis=-1).astype(float)

    def linearize(self, x0: ArrayLike | None = None, u0: ArrayLike | None = None,
                  eps: float = 0.0, d0: ArrayLike | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Exact ``(A, B, E)``: the model is linear, so they do not depend on the point."""
        k = self.params
        wn2 = k.wn**2
        A = np.array([
            [-1 / k.Tv, 0, 0, 0, 0],
            [k.Kvr / k.Tr, -1 / k.Tr, 0, 0, 0],
            [0, 1, 0, 0, 0],
            [k.Kvp * wn2, 0, 0, -2 * k.zeta * k.wn, -wn2],
            [0, 0, 0, 1, 0],
        ], dtype=float)
        B = np.array([[k.Kdv / k.Tv], [k.Kdr / k.Tr], [0], [k.Kdp * wn2], [0]], dtype=float)
        rows = (1, 3) if k.wave_input == "moment" else (2, 4)
        E = np.zeros((5, 2))
        E[rows[0], 0] = E[rows[1], 1] = 1.0
        return A, B, E

    @property
    def C(self) -> FloatArray:
        """Output matrix of the patent's measured channels ``[r, psi, p, phi]`` (= [0 I4])."""
        return np.eye(5)[[self.state_names.index(n) for n in self.measured_names]]
