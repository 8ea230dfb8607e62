"""DP supply vessel: 3-DOF low-frequency model with bias and wave-frequency motion (the DP
wave-frequency patent; docs/models.md section 4).

Low-frequency (LF) model of the L = 76.2 m supply vessel of Fossen, Sagatun & Soerensen (1996),
with a first-order Gauss-Markov bias in NED and one second-order wave-frequency (WF) filter per
degree of freedom (Fossen 2011, ch. 11; Fossen & Strand 1999)::

    eta_dot = R(psi) nu                                  eta = [north_lf, east_lf, psi_lf]
    M nu_dot + D nu = tau + R(psi)^T b                   nu  = [u, v, r] (body axes)
    b_dot   = -T_b^-1 b + E_b w_b                        b   = [b_north, b_east, b_psi] (NED)
    xi_dot  = A_w xi + E_w w_w ,   eta_w = C_w xi        xi  = [xi_1 (3); xi_2 (3)]

    R(psi) = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    M = m Tinv Mbis Tinv ,  D = m sqrt(g/L) Tinv Dbis Tinv ,  Tinv = diag(1, 1, L)
    A_w = [[0, I], [-Omega^2, -2 Lambda Omega]] ,  E_w = [0; diag(K_w)] ,  C_w = [0, I]
    Omega = diag(w0) ,  Lambda = diag(lambda_)

The 15 states are ``[north_lf, east_lf, psi_lf, u, v, r, b_north, b_east, b_psi, xi_north,
xi_east, xi_psi, eta_w_north, eta_w_east, eta_w_psi]``: LF position and heading (m, m, rad), body
velocities (m/s, m/s, rad/s), bias (N, N, N m), the "position-like" WF states xi_1 (m s, m s,
rad s; the time integral of the WF motion) and the WF motion itself xi_2 = eta_w (m, m, rad).
Inputs are the thruster forces and moment ``tau = [X, Y, N]`` (N, N, N m). The six disturbances
``[w_b_north, w_b_east, w_b_psi, w_w_north, w_w_east, w_w_psi]`` are unit-intensity white noises
(unit 1/sqrt(s)); a simulator holding them over a step ``dt`` draws them with std 1/sqrt(dt).

Outputs (:meth:`DPVesselModel.output`) are the states plus what the position reference and the
gyrocompass measure, the DP wave-frequency patent's "LF + WF motion":
``north = north_lf + eta_w_north``, ``east = east_lf + eta_w_east``, ``psi = psi_lf + eta_w_psi``.

The WF gain is set from a target RMS of the WF motion, ``K_w = sqrt(4 lambda w0) sigma_eta``
(unit-intensity noise gives variance K_w^2 / (4 lambda w0)); the bias gain from a stationary bias
std, ``E_b = sigma_b sqrt(2 / T_b)`` (variance E_b^2 T_b / 2). ``T_b = inf`` gives the
``T_b^-1 = 0`` alternative of docs/models.md 4.1 with ``E_b = 0``: a constant bias set by the
initial state. A driven random walk of intensity q is approximated, over any finite episode, by
a long ``T_b`` with ``sigma_b = q sqrt(T_b / 2)``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from ..compiled import Equations, jit
from .base import FloatArray, VehicleModel, require
from .kinematics import planar_to_body, planar_to_ned

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


def wf_matrices(w0: ArrayLike, lambda_: ArrayLike, K_w: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """WF model matrices ``(A_w (6, 6), E_w (6, 3), C_w (3, 6))`` of docs/models.md 4.2.

    Block order: the three "position-like" states xi_1, then the three WF motions xi_2 = eta_w.
    A free function so that estimators can build them for an estimated ``w0``.

    :param w0: peak (modal) frequencies of (north, east, psi), rad/s.
    :param lambda_: relative damping of each filter, -.
    :param K_w: noise gains, m/sqrt(s), m/sqrt(s), rad/sqrt(s).
    """
    w0, lambda_, K_w = (np.broadcast_to(np.asarray(a, dtype=float), (3,))
                        for a in (w0, lambda_, K_w))
    A_w = np.zeros((6, 6))
    A_w[:3, 3:] = np.eye(3)
    A_w[3:, :3] = np.diag(-w0**2)
    A_w[3:, 3:] = np.diag(-2 * lambda_ * w0)
    E_w = np.vstack([np.zeros((3, 3)), np.diag(K_w)])
    C_w = np.hstack([np.zeros((3, 3)), np.eye(3)])
    return A_w, E_w, C_w


def _as_vec3(value, name: str) -> Vec3:
    try:
        vec = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be 3 numbers") from None
    require(len(vec) == 3, name, value, "must be 3 numbers (north/surge, east/sway, yaw)")
    require(all(math.isfinite(v) or v == math.inf for v in vec), name, value,
            "must not be NaN or -inf")
    return vec  # type: ignore[return-value]


def _as_mat3(value, name: str) -> Mat3:
    try:
        mat = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be a 3x3 matrix") from None
    require(mat.shape == (3, 3), name, value, "must be a 3x3 matrix (tuple of 3 rows)")
    require(bool(np.isfinite(mat).all()), name, value, "must be finite")
    return tuple(tuple(float(v) for v in row) for row in mat)  # type: ignore[return-value]


@dataclasses.dataclass(frozen=True)
class DPVesselParams:
    """Parameters of the DP supply-vessel model; names are docs/models.md's symbols. SI units,
    radians.

    Triples are ordered (north or surge, east or sway, yaw); lists are accepted and stored as
    tuples (so JSON-loaded overrides work). ``lambda_`` is docs/models.md's lambda (a Python
    keyword).
    """

    L: float = 76.2  #: length between perpendiculars, m  [CITED: MSS supply.m]
    m: float = 6.0e6  #: mass, kg  [CITED: MSS supply.m]
    g: float = 9.81  #: gravity, m/s^2 (only scales D via the Bis system)  [CITED: MSS supply.m]
    #: non-dimensional (Bis) mass matrix incl. added mass, -  [CITED: MSS supply.m]
    Mbis: Mat3 = ((1.1274, 0.0, 0.0), (0.0, 1.8902, -0.0744), (0.0, -0.0744, 0.1278))
    #: non-dimensional (Bis) linear damping matrix, -  [CITED: MSS supply.m]
    Dbis: Mat3 = ((0.0358, 0.0, 0.0), (0.0, 0.1183, -0.0124), (0.0, -0.0041, 0.0308))
    #: bias time constants, s; inf means T_b^-1 = 0 (constant bias)  [RECALLED: docs/models.md 4.1]
    T_b: Vec3 = (1000.0, 1000.0, 1000.0)
    #: stationary bias std, N, N, N m  [PROPOSED: 50 kN ~ beam wind of 15 m/s on ~600 m^2 of
    #: windage plus current and wave drift in moderate weather; the yaw moment takes a 20 m lever]
    sigma_b: Vec3 = (5.0e4, 5.0e4, 1.0e6)
    w0: Vec3 = (1.2, 1.0, 1.05)  #: WF peak frequencies, rad/s  [SEED]
    lambda_: Vec3 = (0.1, 0.1, 0.1)  #: WF relative damping lambda, -  [SEED]
    #: RMS of the WF motion, m, m, rad  [PROPOSED: docs/models.md 4.2, 1 m, 1 m, 2 deg]
    sigma_eta: Vec3 = (1.0, 1.0, math.radians(2.0))
    #: thrust limits |X|, |Y|, |N|, N, N, N m  [PROPOSED: see DPVesselModel.u_bounds]
    tau_max: Vec3 = (6.0e5, 4.0e5, 1.5e7)

    def __post_init__(self) -> None:
        for name in ("L", "m", "g"):
            value = getattr(self, name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            require(math.isfinite(number) and number > 0, name, value,
                    "must be a finite number > 0")
            object.__setattr__(self, name, number)
        for name in ("Mbis", "Dbis"):
            object.__setattr__(self, name, _as_mat3(getattr(self, name), name))
        for name in ("T_b", "sigma_b", "w0", "lambda_", "sigma_eta", "tau_max"):
            object.__setattr__(self, name, _as_vec3(getattr(self, name), name))
        Mbis, Dbis = np.array(self.Mbis), np.array(self.Dbis)
        require(np.allclose(Mbis, Mbis.T, rtol=1e-12, atol=0), "Mbis", self.Mbis,
                "must be symmetric (M = M^T > 0)")
        require(bool(np.all(np.linalg.eigvalsh(Mbis) > 0)), "Mbis", self.Mbis,
                "must be positive definite (M = M^T > 0)")
        require(bool(np.all(np.linalg.eigvalsh(Dbis + Dbis.T) > 0)), "Dbis", self.Dbis,
                "must have a positive definite symmetric part (D + D^T > 0: dissipative)")
        require(all(v > 0 for v in self.T_b), "T_b", self.T_b, "must be > 0 (inf allowed)")
        finite = {"sigma_b": ">= 0", "w0": "> 0", "sigma_eta": ">= 0", "tau_max": "> 0"}
        for name, rule in finite.items():
            vec = getattr(self, name)
            ok = all(math.isfinite(v) and (v >= 0 if rule == ">= 0" else v > 0) for v in vec)
            require(ok, name, vec, f"must be finite and {rule}")
        # 0 < lambda < 1: the WF filter is a resonant (under-damped) narrow-band model
        require(all(0 < v < 1 for v in self.lambda_), "lambda_", self.lambda_,
                "must be in (0, 1)")

    # -- derived matrices (docs/models.md 4.1, 4.2) --------------------------------------------
    @property
    def M(self) -> FloatArray:
        """Mass matrix incl. added mass, ``m Tinv Mbis Tinv`` (kg, kg, kg m, kg m^2)."""
        Tinv = np.diag([1.0, 1.0, self.L])
        return self.m * Tinv @ np.array(self.Mbis) @ Tinv

    @property
    def D(self) -> FloatArray:
        """Linear damping, ``m sqrt(g/L) Tinv Dbis Tinv`` (N s/m, N s, N m s)."""
        Tinv = np.diag([1.0, 1.0, self.L])
        return self.m * math.sqrt(self.g / self.L) * Tinv @ np.array(self.Dbis) @ Tinv

    @property
    def E_b(self) -> FloatArray:
        """Bias noise gains ``sigma_b sqrt(2 / T_b)``, shape (3,), N/sqrt(s), N m/sqrt(s)."""
        return np.array(self.sigma_b) * np.sqrt(2.0 / np.array(self.T_b))

    @property
    def K_w(self) -> FloatArray:
        """WF noise gains ``sqrt(4 lambda w0) sigma_eta``, shape (3,), m/sqrt(s), rad/sqrt(s)."""
        return np.sqrt(4 * np.array(self.lambda_) * np.array(self.w0)) * np.array(self.sigma_eta)

    @property
    def A_w(self) -> FloatArray:
        """WF system matrix (6, 6), block order [xi_1; xi_2]."""
        return wf_matrices(self.w0, self.lambda_, self.K_w)[0]

    @property
    def E_w(self) -> FloatArray:
        """WF noise input matrix (6, 3) = ``[0; diag(K_w)]``."""
        return wf_matrices(self.w0, self.lambda_, self.K_w)[1]

    @property
    def C_w(self) -> FloatArray:
        """WF output matrix (3, 6) = ``[0, I]``: eta_w = C_w xi."""
        return wf_matrices(self.w0, self.lambda_, self.K_w)[2]


#: Layout of the packed constants ``p`` of :func:`dp_vessel_rhs` (see :meth:`DPVesselModel.pack`):
#: M^-1 and M^-1 D row by row, then per degree of freedom 1/T_b, E_b, w0^2, 2 lambda w0, K_w.
MINV, MINV_D, INV_TB, E_B, W0_SQ, TWO_LAMBDA_W0, K_W = 0, 9, 18, 21, 24, 27, 30


@jit
def dp_vessel_rhs(x, u, d, p, out):
    """One vessel's ``x_dot`` (module docstring); ``p`` packed by :meth:`DPVesselModel.pack`."""
    c, s = np.cos(x[2]), np.sin(x[2])
    out[0], out[1] = planar_to_ned(c, s, x[3], x[4])  # R(psi) nu
    out[2] = x[5]
    # M nu_dot = tau + R(psi)^T b - D nu
    bias_x, bias_y = planar_to_body(c, s, x[6], x[7])
    f0, f1, f2 = u[0] + bias_x, u[1] + bias_y, u[2] + x[8]
    for i in range(3):
        m, md = MINV + 3 * i, MINV_D + 3 * i
        out[3 + i] = (p[m] * f0 + p[m + 1] * f1 + p[m + 2] * f2) \
            - (p[md] * x[3] + p[md + 1] * x[4] + p[md + 2] * x[5])
        out[6 + i] = -p[INV_TB + i] * x[6 + i] + p[E_B + i] * d[i]
        out[9 + i] = x[12 + i]  # xi_1_dot = xi_2
        out[12 + i] = -p[W0_SQ + i] * x[9 + i] - p[TWO_LAMBDA_W0 + i] * x[12 + i] \
            + p[K_W + i] * d[3 + i]


class DPVesselModel(VehicleModel):
    """Dynamically positioned supply vessel (the DP wave-frequency patent): LF + bias + WF model,
    15 states."""

    name: ClassVar[str] = "dp_vessel"
    state_names: ClassVar[tuple[str, ...]] = (
        "north_lf", "east_lf", "psi_lf", "u", "v", "r", "b_north", "b_east", "b_psi",
        "xi_north", "xi_east", "xi_psi", "eta_w_north", "eta_w_east", "eta_w_psi")
    input_names: ClassVar[tuple[str, ...]] = ("X", "Y", "N")
    disturbance_names: ClassVar[tuple[str, ...]] = (
        "w_b_north", "w_b_east", "w_b_psi", "w_w_north", "w_w_east", "w_w_psi")
    state_units: ClassVar[tuple[str, ...]] = (
        "m", "m", "rad", "m/s", "m/s", "rad/s", "N", "N", "N m",
        "m s", "m s", "rad s", "m", "m", "rad")
    input_units: ClassVar[tuple[str, ...]] = ("N", "N", "N m")
    disturbance_units: ClassVar[tuple[str, ...]] = ("1/sqrt(s)",) * 6
    #: The DP wave-frequency patent's measured channels: position reference and gyrocompass see
    #: LF + WF motion.
    measured_names: ClassVar[tuple[str, ...]] = ("north", "east", "psi")
    is_linear: ClassVar[bool] = False  # R(psi)
    noise_model_states: ClassVar[tuple[str, ...]] = state_names[6:]
    equations: ClassVar[Equations] = Equations(dp_vessel_rhs)

    def __init__(self, params: DPVesselParams | None = None) -> None:
        super().__init__(DPVesselParams() if params is None else params)
        k = self.params
        self._Minv = np.linalg.inv(k.M)
        self._MinvD = self._Minv @ k.D
        self._inv_Tb = 1.0 / np.array(k.T_b)  # 0 for T_b = inf
        self._E_b = k.E_b

    def pack(self) -> FloatArray:
        """The constants of :func:`dp_vessel_rhs`, derived once: it runs 8x per control step."""
        k = self.params
        w0 = np.array(k.w0)
        return np.concatenate([self._Minv.ravel(), self._MinvD.ravel(), self._inv_Tb, self._E_b,
                               w0**2, 2 * np.array(k.lambda_) * w0, k.K_w])

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Box limits on ``tau`` (N, N, N m), each channel's capacity alone [PROPOSED].

        Sized for a 76 m, 6000 t platform supply vessel of the UT-7xx class: two main CP
        propellers of ~2.5 MW (~80 t bollard pull ahead, less astern) -> |X| <= 600 kN; two bow
        tunnels of ~900 kW (~110 kN each) plus one stern tunnel (~100 kN) and rudder lift ->
        |Y| <= 400 kN; the bow tunnels at ~+30 m and stern tunnel and rudders at ~-33 m ->
        |N| <= 1.5e7 N m. The default bias at 3 sigma, in any heading, needs at most
        3 sqrt(2) 50 kN = 212 kN and 3 MN m, leaving margin for control.
        """
        high = np.array(self.params.tau_max)
        return -high, high

    # -- dynamics ------------------------------------------------------------------------------
    def linearize(self, x0: ArrayLike | None = None, u0: ArrayLike | None = None,
                  eps: float = 0.0, d0: ArrayLike | None = None
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Exact Jacobians ``(A, B, E)`` of :meth:`rhs` at ``(x0, u0)`` (the disturbances enter
        linearly: ``d0`` changes nothing).

        Only the heading enters nonlinearly (through R(psi)), so the derivatives are analytic;
        ``eps`` is ignored (kept for the base-class signature). ``B`` and ``E`` are constant.
        """
        x0 = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        if x0.shape != (15,):
            raise ValueError(f"x0 must have shape (15,), got {x0.shape}")
        psi, (u, v, _), (b_n, b_e, _) = x0[2], x0[3:6], x0[6:9]
        c, s = math.cos(psi), math.sin(psi)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        A = np.zeros((15, 15))
        A[0:3, 3:6] = R
        A[0:2, 2] = (-s * u - c * v, c * u - s * v)  # dR/dpsi nu
        A[3:6, 3:6] = -self._MinvD
        A[3:6, 6:9] = self._Minv @ R.T
        A[3:6, 2] = self._Minv @ np.array([-s * b_n + c * b_e, -c * b_n - s * b_e, 0.0])
        A[6:9, 6:9] = np.diag(-self._inv_Tb)
        A[9:15, 9:15] = self.params.A_w
        B = np.zeros((15, 3))
        B[3:6] = self._Minv
        E = np.zeros((15, 6))
        E[6:9, :3] = np.diag(self._E_b)
        E[9:15, 3:] = self.params.E_w
        return A, B, E

    # -- outputs -------------------------------------------------------------------------------
    @property
    def output_names(self) -> tuple[str, ...]:
        """The states, then the measurable total motion ``north, east, psi`` (LF + WF)."""
        return self.state_names + self.measured_names

    @property
    def output_units(self) -> tuple[str, ...]:
        return self.state_units + ("m", "m", "rad")

    def output(self, x: FloatArray) -> FloatArray:
        """States and total motion ``eta_lf + eta_w``, shape ``(..., 18)``."""
        x = np.asarray(x, dtype=float)
        return np.concatenate([x, x[..., 0:3] + x[..., 12:15]], axis=-1)


__all__ = ["DPVesselModel", "DPVesselParams", "wf_matrices"]
