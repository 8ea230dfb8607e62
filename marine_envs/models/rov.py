"""ROV/AUV with a morphing hull, Prestero REMUS-100 coefficients (seed 002; MODELS.md section 3).

Six-degree-of-freedom rigid body with the body origin at the centre of buoyancy (CB), SNAME/NED
axes (x forward, y starboard, z down), ZYX Euler angles. ``x = [u v w p q r  x y z  phi theta psi
s]``: body velocities nu (m/s, rad/s), NED position (m, z down), Euler angles (rad) and the morph
fraction ``s`` (0 = cruise, 1 = work shape, manipulator deployed at the bow). ``u = tau = [X Y Z K
M N]``: generalised forces at the CB (N, N m). ``d = [current_n current_e current_d s_cmd]``: a
constant, irrotational ocean current in NED (m/s) and the morph command (-). MODELS.md 3.2::

    (M_RB(s) + M_A) nu_dot = -C_RB(nu, s) nu + tau_hyd(nu_r, s) + tau_s(eta, s) + tau
    eta_dot = J(eta) nu                     (ZYX Euler kinematics, NED position from nu)
    s_dot   = (s_cmd - s) / T_m

    M_RB = [[m I3, -m S(r_G)], [m S(r_G), I_b]],   I_b = diag(Ixx, Iyy, Izz) about the CB
    M_A  = -[[Xud,0,0,0,0,0], [0,Yvd,0,0,0,Yrd], [0,0,Zwd,0,Zqd,0],
             [0,0,0,Kpd,0,0], [0,0,Mwd,0,Mqd,0], [0,Nvd,0,0,0,Nrd]]
    -C_RB nu = [-m (w x nu1 + w x (w x r_G)) ;  -m r_G x (w x nu1) - w x (I_b w)],  w = [p q r]
        (Fossen's C_RB parameterisation independent of the linear velocity; no C_A: the
        added-mass Coriolis/Munk terms are already inside Prestero's combined coefficients)

    tau_hyd (Prestero's combined coefficients, on nu_r = [u_r v_r w_r p q r]):
    X = Xuu u|u| + Xwq w q + Xqq q q + Xvr v r + Xrr r r
    Y = Yvv v|v| + Yrr r|r| + Yuv u v + Ywp w p + Yur u r + Ypq p q
    Z = Zww w|w| + Zqq q|q| + Zuw u w + Zvp v p + Zuq u q + Zrp r p
    K = Kpp p|p|
    M = Mww w|w| + Mqq q|q| + Muw u w + Muq u q + Mvp v p + Mrp r p
    N = Nvv v|v| + Nrr r|r| + Nuv u v + Nur u r + Nwp w p + Npq p q

    tau_s (restoring; g = r_G W - r_B B):
    X_s = -(W-B) sin(theta)          K_s = g_y cos(theta) cos(phi) - g_z cos(theta) sin(phi)
    Y_s =  (W-B) cos(theta) sin(phi) M_s = -g_z sin(theta) - g_x cos(theta) cos(phi)
    Z_s =  (W-B) cos(theta) cos(phi) N_s =  g_x cos(theta) sin(phi) + g_y sin(theta)

**Current.** ``nu_r = nu - [R(eta)^T v_c; 0 0 0]`` with ``v_c`` the NED current: the
hydrodynamic terms act on the velocity relative to the water, the rigid-body Coriolis terms and
the kinematics on ``nu`` (velocity over ground). Approximation (documented choice): the current is
constant and irrotational, and the added-mass inertia multiplies ``nu_dot`` instead of
``nu_r_dot = nu_dot + w x nu_c``; the neglected force is ``M_A (w x nu_c)``, small for slow
currents and turn rates, and zero without current.

**Morph** [PROPOSED, MODELS.md 3.4]. Every quadratic coefficient that the deployed arm changes,
``r_G``, ``r_B`` and ``I_b`` are interpolated as ``theta(s) = theta_c + s (theta_w - theta_c)``;
``m``, ``W``, ``B``, the added mass and the cross-flow/lift coefficients do not change. ``s`` is
not clipped: a command outside [0, 1] extrapolates linearly. The optional +5 % added mass of the
flooded bay (MODELS.md 3.4) is not modelled.

**Actuation.** The inputs are generalised forces: an idealised, fully actuated vehicle. The
[PROPOSED] six-thruster layout of MODELS.md 3.5 (:data:`THRUSTER_ALLOCATION`, :func:`allocate`)
gives the bounds of X, Y, Z, M and N (the box of each row's reachable range; the jointly reachable
set is smaller, e.g. X and N share the stern thrusters). Its roll row is zero, so K gets a small
[PROPOSED] idealised range +-K_max; with thrusters only, roll is passively stable through BG.
In work shape the bow-down moment ``x_G W - x_B B = 11.3 N m`` exceeds the thrusters' pitch range
(7.5 N m): holding the work-shape boat level needs the seed's variable-structure device.

**Implementation.** ``rhs`` is written for batches: the right-hand side is linear in a feature
matrix ``F`` of products (``u|u|``, ``w q``, ``sin(theta)``, ``tau``, ...) and, for the morph, of
the same features times ``s``, so ``tau_total = [F, s F] @ [C_cruise; C_work - C_cruise]`` is one
GEMM. ``M(s) = M_0 + s (M_1 - M_0)`` is inverted exactly for every ``s`` from the generalised
eigen-decomposition ``(M_1 - M_0) V = M_0 V diag(lam)``, ``V^T M_0 V = I``:
``M(s)^-1 = V diag(1 / (1 + s lam)) V^T``; it is folded into the coefficient matrix.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike

from .base import FloatArray, VehicleModel, require

# -- thrusters (MODELS.md 3.5, [PROPOSED]) ------------------------------------------------------
#: Thruster positions relative to the CB, m (rows: stern port, stern stbd, bow lateral, stern
#: lateral, bow vertical, stern vertical).
THRUSTER_POSITIONS: FloatArray = np.array([
    [-0.60, -0.10, 0.0], [-0.60, 0.10, 0.0], [0.40, 0.0, 0.0],
    [-0.45, 0.0, 0.0], [0.35, 0.0, 0.0], [-0.40, 0.0, 0.0]])
#: Unit thrust directions in body axes.
THRUSTER_DIRECTIONS: FloatArray = np.array([
    [1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 1.0]])
#: Allocation matrix B_T (6x6): tau = B_T f, column i = [d_i; r_i x d_i]. Rank 5, zero roll row.
THRUSTER_ALLOCATION: FloatArray = np.vstack([
    THRUSTER_DIRECTIONS.T, np.cross(THRUSTER_POSITIONS, THRUSTER_DIRECTIONS).T])
#: Thrust limits (low, high) of each thruster, N.
THRUSTER_LIMITS: tuple[FloatArray, FloatArray] = (
    np.array([-20.0, -20.0, -10.0, -10.0, -10.0, -10.0]),
    np.array([30.0, 30.0, 10.0, 10.0, 10.0, 10.0]))
for _a in (THRUSTER_POSITIONS, THRUSTER_DIRECTIONS, THRUSTER_ALLOCATION, *THRUSTER_LIMITS):
    _a.flags.writeable = False
_ALLOCATION_PINV_T = np.linalg.pinv(THRUSTER_ALLOCATION).T


def allocate(tau: ArrayLike) -> FloatArray:
    """Thruster forces for generalised forces ``tau`` (shape ``(..., 6)``, N and N m):
    ``f = pinv(B_T) tau``, then saturated to :data:`THRUSTER_LIMITS` (shape ``(..., 6)``, N).

    The roll component of ``tau`` is ignored (no roll authority); saturation is per thruster, so a
    saturated ``f`` no longer reproduces ``tau`` exactly.
    """
    f = np.asarray(tau, dtype=float) @ _ALLOCATION_PINV_T
    return np.clip(f, *THRUSTER_LIMITS)


def _thruster_box() -> tuple[FloatArray, FloatArray]:
    """Per-row reachable range of B_T f over the thruster limits (a box, not the exact set)."""
    low, high = THRUSTER_LIMITS
    ends = np.stack([THRUSTER_ALLOCATION * low, THRUSTER_ALLOCATION * high])
    return ends.min(axis=0).sum(axis=1), ends.max(axis=0).sum(axis=1)


# -- parameters ---------------------------------------------------------------------------------
#: Quantities that the morph changes (MODELS.md 3.4); each has a ``work_<name>`` field.
MORPHING: tuple[str, ...] = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr", "Yrr", "Zqq", "Mww", "Nvv",
                             "xG", "yG", "zG", "xB", "yB", "zB", "Ixx", "Iyy", "Izz")
#: Hydrodynamic coefficients of tau_hyd, in MODELS.md 3.2 order.
HYDRO_COEFFICIENTS: tuple[str, ...] = (
    "Xuu", "Xwq", "Xqq", "Xvr", "Xrr", "Yvv", "Yrr", "Yuv", "Ywp", "Yur", "Ypq",
    "Zww", "Zqq", "Zuw", "Zvp", "Zuq", "Zrp", "Kpp", "Mww", "Mqq", "Muw", "Muq", "Mvp", "Mrp",
    "Nvv", "Nrr", "Nuv", "Nur", "Nwp", "Npq")
_SHAPE = (*HYDRO_COEFFICIENTS, "xG", "yG", "zG", "xB", "yB", "zB", "Ixx", "Iyy", "Izz")
_DISSIPATIVE = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr")
_ADDED_MASS_DIAGONAL = ("Xud", "Yvd", "Zwd", "Kpd", "Mqd", "Nrd")


@dataclasses.dataclass(frozen=True)
class ROVParams:
    """Parameters of the ROV model; names are MODELS.md's symbols (``Xuu`` = X_u|u|, ``Xud`` =
    X_u-dot). SI units, radians. Cruise values: Prestero's REMUS-100 (MODELS.md 3.3, [CITED] via
    the DSTO ``remus100_withM.m`` listing and GTRI SCRIMMAGE ``UUV6DOF.xml`` unless tagged);
    ``work_*``: the work shape's absolute values (MODELS.md 3.4 table, [PROPOSED])."""

    # rigid body, origin at the CB
    m: float = 30.48  #: mass, kg  [CITED]
    W: float = 299.0  #: weight, N  [CITED]
    B: float = 306.0  #: buoyancy, N  [CITED]
    rho: float = 1030.0  #: water density, kg/m^3 [CITED]; provenance only: coefficients are dimensional
    xG: float = 0.0  #: centre of gravity rel. CB, m  [CITED]
    yG: float = 0.0  #: m  [CITED]
    zG: float = 0.0196  #: m (below the CB)  [CITED]
    xB: float = 0.0  #: centre of buoyancy rel. origin, m (origin at the CB)  [CITED]
    yB: float = 0.0  #: m  [CITED]
    zB: float = 0.0  #: m  [CITED]
    Ixx: float = 0.177  #: roll inertia about the CB, kg m^2  [CITED]
    Iyy: float = 3.45  #: kg m^2  [CITED]
    Izz: float = 3.45  #: kg m^2  [CITED]
    # added mass (unchanged by the morph)
    Xud: float = -0.93  #: kg  [CITED]
    Yvd: float = -35.5  #: kg  [CITED]
    Zwd: float = -35.5  #: kg  [CITED]
    Kpd: float = -0.0141  #: kg m^2  [CITED: Prestero/SCRIMMAGE; DSTO's revised -0.0704 not used]
    Mqd: float = -4.88  #: kg m^2  [CITED]
    Nrd: float = -4.88  #: kg m^2  [CITED]
    Yrd: float = 1.93  #: kg m  [CITED]
    Nvd: float = 1.93  #: kg m  [CITED]
    Zqd: float = -1.93  #: kg m  [CITED]
    Mwd: float = -1.93  #: kg m  [CITED]
    # combined hydrodynamic coefficients, cruise shape (MODELS.md 3.3)
    Xuu: float = -1.62  #: kg/m  [CITED]
    Yvv: float = -131.0  #: kg/m  [CITED: SCRIMMAGE/Prestero; DSTO lists -1310]
    Zww: float = -131.0  #: kg/m  [CITED: SCRIMMAGE/Prestero; DSTO lists -1310]
    Yrr: float = 0.632  #: kg m/rad^2  [CITED]
    Zqq: float = -0.632  #: kg m/rad^2  [CITED]
    Mww: float = 3.18  #: kg  [CITED]
    Nvv: float = -3.18  #: kg  [CITED]
    Mqq: float = -188.0  #: kg m^2/rad^2  [CITED: Prestero; SCRIMMAGE's -9.4 not used]
    Nrr: float = -94.0  #: kg m^2/rad^2  [CITED]
    Kpp: float = -1.30e-3  #: kg m^2/rad^2  [RECALLED: Prestero; DSTO lists -0.130]
    Yuv: float = -28.6  #: kg/m  [CITED]
    Zuw: float = -28.6  #: kg/m  [CITED]
    Yur: float = 5.22  #: kg/rad  [CITED]
    Zuq: float = -5.22  #: kg/rad  [CITED]
    Muw: float = 24.0  #: kg  [CITED]
    Nuv: float = -24.0  #: kg  [CITED]
    Muq: float = -2.0  #: kg m/rad  [CITED]
    Nur: float = -2.0  #: kg m/rad  [CITED]
    Xwq: float = -35.5  #: kg/rad  [CITED]
    Ywp: float = 35.5  #: kg/rad  [CITED]
    Zvp: float = -35.5  #: kg/rad  [CITED]
    Xvr: float = 35.5  #: kg/rad  [CITED]
    Xqq: float = -1.93  #: kg m/rad  [CITED]
    Xrr: float = -1.93  #: kg m/rad  [CITED]
    Ypq: float = 1.93  #: kg m/rad  [CITED]
    Zrp: float = 1.93  #: kg m/rad  [CITED]
    Mvp: float = -1.93  #: kg m/rad  [CITED]
    Nwp: float = -1.93  #: kg m/rad  [CITED]
    Mrp: float = 4.86  #: kg m^2/rad^2  [CITED]
    Npq: float = -4.86  #: kg m^2/rad^2  [CITED]
    # morph: first-order lag and the work shape (absolute values, not increments)
    T_m: float = 5.0  #: morph time constant, s  [PROPOSED]
    work_Xuu: float = -15.30  #: kg/m  [PROPOSED]
    work_Yvv: float = -142.33  #: kg/m  [PROPOSED]
    work_Zww: float = -139.01  #: kg/m  [PROPOSED]
    work_Yrr: float = -6.52  #: kg m/rad^2  [PROPOSED]
    work_Zqq: float = 4.42  #: kg m/rad^2  [PROPOSED]
    work_Mww: float = 9.49  #: kg  [PROPOSED]
    work_Mqq: float = -192.11  #: kg m^2/rad^2  [PROPOSED]
    work_Nvv: float = -12.11  #: kg  [PROPOSED]
    work_Nrr: float = -99.82  #: kg m^2/rad^2  [PROPOSED]
    work_Kpp: float = -0.214  #: kg m^2/rad^2  [PROPOSED]
    work_xG: float = 0.0480  #: m  [PROPOSED]
    work_yG: float = 0.0  #: m  [PROPOSED]
    work_zG: float = 0.0419  #: m  [PROPOSED]
    work_xB: float = 0.0101  #: m  [PROPOSED]
    work_yB: float = 0.0  #: m  [PROPOSED]
    work_zB: float = 0.0047  #: m  [PROPOSED]
    work_Ixx: float = 0.331  #: kg m^2  [PROPOSED]
    work_Iyy: float = 5.196  #: kg m^2  [PROPOSED]
    work_Izz: float = 5.042  #: kg m^2  [PROPOSED]
    # actuation
    K_max: float = 1.0  #: idealised roll-moment bound, N m  [PROPOSED: thrusters have none]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            require(isinstance(value, (int, float)) and math.isfinite(value), f.name, value,
                    "must be a finite number")
        positive = ("m", "W", "B", "rho", "T_m", "K_max", "Ixx", "Iyy", "Izz",
                    "work_Ixx", "work_Iyy", "work_Izz")
        for name in positive:
            require(getattr(self, name) > 0, name, getattr(self, name), "must be > 0")
        for name in (*_DISSIPATIVE, *(f"work_{n}" for n in _DISSIPATIVE), *_ADDED_MASS_DIAGONAL):
            require(getattr(self, name) <= 0, name, getattr(self, name),
                    "must be <= 0 (dissipative damping / positive added mass)")
        for s in (0.0, 1.0):
            mass = mass_matrix(self, s)
            eig = np.linalg.eigvalsh(0.5 * (mass + mass.T))
            require(bool(eig.min() > 0), f"M_RB + M_A at s={s:g}", eig.round(6).tolist(),
                    "must be positive definite (check m, xG/yG/zG, Ixx/Iyy/Izz, their work_ "
                    "values and the added-mass derivatives)")

    def shape_at(self, s: float) -> dict[str, float]:
        """Every morphing quantity at morph fraction ``s``: hydrodynamic coefficients, ``r_G``,
        ``r_B`` (m) and ``I_b`` (kg m^2), ``theta(s) = theta_c + s (theta_w - theta_c)``, keyed by
        the cruise names. Non-morphing coefficients are included unchanged."""
        out = {}
        for name in _SHAPE:
            cruise = getattr(self, name)
            out[name] = (cruise + s * (getattr(self, f"work_{name}") - cruise)
                         if name in MORPHING else cruise)
        return out


def mass_matrix(params: ROVParams, s: float = 0.0) -> FloatArray:
    """``M_RB(s) + M_A`` (6x6, kg, kg m, kg m^2) at morph fraction ``s``."""
    k, c = params, params.shape_at(s)
    mS = k.m * _skew(np.array([c["xG"], c["yG"], c["zG"]]))
    rigid = np.block([[k.m * np.eye(3), -mS], [mS, np.diag([c["Ixx"], c["Iyy"], c["Izz"]])]])
    added = -np.array([[k.Xud, 0, 0, 0, 0, 0], [0, k.Yvd, 0, 0, 0, k.Yrd],
                       [0, 0, k.Zwd, 0, k.Zqd, 0], [0, 0, 0, k.Kpd, 0, 0],
                       [0, 0, k.Mwd, 0, k.Mqd, 0], [0, k.Nvd, 0, 0, 0, k.Nrd]])
    return rigid + added


def _skew(a: FloatArray) -> FloatArray:
    """S(a) with S(a) b = a x b."""
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


# -- feature layout of the batched right-hand side (rows of F^T) --------------------------------
_ABS = slice(0, 6)  # nu_r|nu_r|: u, v, w, p, q, r
_UV, _UW = 6, 7  # u_r v_r, u_r w_r
_OMR = slice(8, 17)  # omega_i nu_r_j, index 8 + 3 i + j (i: p q r, j: u v w)
_OMN = slice(17, 26)  # omega_i nu_j (rigid-body Coriolis, over ground)
_ANG = slice(26, 32)  # p p, q q, r r, p q, p r, q r
_RES = slice(32, 35)  # sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)
_TAU = slice(35, 41)  # X Y Z K M N
_N_BASE = 41
# features whose coefficients depend on s, and where their s-multiples go
_MORPH_SRC = (slice(0, 6), slice(17, 35))
_MORPH_DST = (slice(41, 47), slice(47, 65))
_N_FEATURES = 65
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_X, _Y, _Z, _K, _M, _N = range(6)


def _coefficient_matrix(k: ROVParams, c: dict[str, float]) -> FloatArray:
    """(41, 6) matrix C with tau_total = F_base @ C for the shape ``c`` (affine in ``c``)."""
    C = np.zeros((_N_BASE, 6))
    om = lambda i, j: 8 + 3 * i + j  # noqa: E731  (omega_i * nu_r_j)
    entries = {
        (0, _X): "Xuu", (1, _Y): "Yvv", (1, _N): "Nvv", (2, _Z): "Zww", (2, _M): "Mww",
        (3, _K): "Kpp", (4, _Z): "Zqq", (4, _M): "Mqq", (5, _Y): "Yrr", (5, _N): "Nrr",
        (_UV, _Y): "Yuv", (_UV, _N): "Nuv", (_UW, _Z): "Zuw", (_UW, _M): "Muw",
        (om(0, 1), _Z): "Zvp", (om(0, 1), _M): "Mvp", (om(0, 2), _Y): "Ywp",
        (om(0, 2), _N): "Nwp", (om(1, 0), _Z): "Zuq", (om(1, 0), _M): "Muq",
        (om(1, 2), _X): "Xwq", (om(2, 0), _Y): "Yur", (om(2, 0), _N): "Nur",
        (om(2, 1), _X): "Xvr", (27, _X): "Xqq", (28, _X): "Xrr", (29, _Y): "Ypq",
        (29, _N): "Npq", (30, _Z): "Zrp", (30, _M): "Mrp",
    }
    for (row, col), name in entries.items():
        C[row, col] = c[name]
    # rigid-body Coriolis, linear part: a = omega x nu1 = eps_kij omega_i nu_j
    r_G = np.array([c["xG"], c["yG"], c["zG"]])
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    a_map = eps.transpose(1, 2, 0).reshape(9, 3)  # row 3 i + j -> coefficient of a_k
    C[_OMN, :3] = -k.m * a_map
    C[_OMN, 3:] = -k.m * a_map @ _skew(r_G).T  # -m r_G x a
    # rigid-body Coriolis, angular part: -m w x (w x r_G) and -w x (I w), exact monomial split
    inertia = np.array([c["Ixx"], c["Iyy"], c["Izz"]])

    def quad(w: FloatArray) -> FloatArray:
        return np.concatenate([-k.m * np.cross(w, np.cross(w, r_G)), -np.cross(w, inertia * w)])

    unit = np.eye(3)
    for row, (i, j) in enumerate(_PAIRS, start=_ANG.start):
        C[row] += quad(unit[i]) if i == j else quad(unit[i] + unit[j]) - quad(unit[i]) \
            - quad(unit[j])
    # restoring forces
    wb = k.W - k.B
    gx, gy, gz = r_G * k.W - np.array([c["xB"], c["yB"], c["zB"]]) * k.B
    C[32, [_X, _M, _N]] = -wb, -gz, gy
    C[33, [_Y, _K, _N]] = wb, -gz, gx
    C[34, [_Z, _K, _M]] = wb, gy, -gx
    C[_TAU] = np.eye(6)
    return C


class ROVModel(VehicleModel):
    """REMUS-100-type AUV/ROV with a cruise/work morphing hull (seed 002; MODELS.md 3)."""

    name: ClassVar[str] = "rov"
    state_names: ClassVar[tuple[str, ...]] = (
        "u", "v", "w", "p", "q", "r", "x", "y", "z", "phi", "theta", "psi", "s")
    input_names: ClassVar[tuple[str, ...]] = ("X", "Y", "Z", "K", "M", "N")
    disturbance_names: ClassVar[tuple[str, ...]] = ("current_n", "current_e", "current_d", "s_cmd")
    state_units: ClassVar[tuple[str, ...]] = (
        "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s", "m", "m", "m", "rad", "rad", "rad", "-")
    input_units: ClassVar[tuple[str, ...]] = ("N", "N", "N", "N m", "N m", "N m")
    disturbance_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "m/s", "-")
    #: Nominal cruise: REMUS cruise speed, m/s, and depth, m.
    cruise_speed: ClassVar[float] = 1.5
    cruise_depth: ClassVar[float] = 5.0

    def __init__(self, params: ROVParams | None = None) -> None:
        super().__init__(ROVParams() if params is None else params)
        k = self.params
        c0, c1 = k.shape_at(0.0), k.shape_at(1.0)
        base0 = _coefficient_matrix(k, c0)
        delta = _coefficient_matrix(k, c1) - base0
        coeffs = np.zeros((_N_FEATURES, 6))
        coeffs[:_N_BASE] = base0
        keep = np.zeros(_N_BASE, dtype=bool)
        for src, dst in zip(_MORPH_SRC, _MORPH_DST, strict=True):
            coeffs[dst] = delta[src]
            keep[src] = True
        assert not delta[~keep].any(), "a morphing coefficient outside the morph features"
        self._coeffs = coeffs  # tau_total = [F, s F] @ coeffs
        # exact M(s)^-1 = V diag(1/(1 + s lam)) L for M(s) = M0 + s dM
        M0, dM = mass_matrix(k, 0.0), mass_matrix(k, 1.0) - mass_matrix(k, 0.0)
        if np.array_equal(M0, M0.T) and np.array_equal(dM, dM.T):
            lam, V = scipy.linalg.eigh(dM, M0)  # V^T M0 V = I
            L = V.T
        else:  # non-symmetric added mass (Yrd != Nvd or Zqd != Mwd): general eigenproblem
            lam, V = np.linalg.eig(np.linalg.solve(M0, dM))
            require(bool(np.all(np.abs(lam.imag) < 1e-9 * (1 + np.abs(lam.real))))
                    and np.linalg.cond(V) < 1e8, "added mass (Yrd, Nvd, Zqd, Mwd)",
                    (k.Yrd, k.Nvd, k.Zqd, k.Mwd), "too far from symmetric for the exact "
                    "morph inverse")
            lam, V = lam.real, V.real
            L = np.linalg.solve(V, np.linalg.inv(M0))
        self._lam = np.ascontiguousarray(lam[:, None])  # (6, 1)
        self._V = np.ascontiguousarray(V)
        self._GT = np.ascontiguousarray((coeffs @ L.T).T)  # (6, 65): y = GT @ F^T
        self._inv_T_m = 1.0 / k.T_m
        self._x0 = np.zeros(len(self.state_names))
        self._x0[[0, 8]] = self.cruise_speed, self.cruise_depth
        self._u0 = self.trim_forces(self.cruise_speed, 0.0)
        low, high = _thruster_box()
        low[_K], high[_K] = -k.K_max, k.K_max
        self._u_bounds = (low, high)

    # -- nominal point and bounds ------------------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Cruise at ``u = 1.5 m/s``, depth 5 m, level, heading north, cruise shape (s = 0)."""
        return self._x0.copy()

    @property
    def u0(self) -> FloatArray:
        """Generalised forces holding :attr:`x0` at zero acceleration (``x`` still grows at
        1.5 m/s): surge thrust against the drag and heave force against the net buoyancy."""
        return self._u0.copy()

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Box of the thruster layout's reachable range per row (X [-40, 60] N, Y and Z +-20 N,
        M +-7.5 N m, N +-13.5 N m) and the idealised roll moment +-K_max."""
        return self._u_bounds[0].copy(), self._u_bounds[1].copy()

    def coefficients(self, s: float) -> dict[str, float]:
        """Interpolated coefficients, r_G, r_B and I_b at morph fraction ``s`` (see
        :meth:`ROVParams.shape_at`)."""
        return self.params.shape_at(s)

    def mass_matrix(self, s: float = 0.0) -> FloatArray:
        """``M_RB(s) + M_A`` (6x6) at morph fraction ``s``."""
        return mass_matrix(self.params, s)

    def trim_forces(self, u_speed: float, s: float = 0.0) -> FloatArray:
        """Generalised forces (N, N m) that hold steady, level, straight motion at surge speed
        ``u_speed`` (m/s) in still water with the hull held at shape ``s`` (``s_cmd = s``)."""
        x = np.zeros(len(self.state_names))
        x[[0, 8, 12]] = u_speed, self.cruise_depth, s
        d = np.array([0.0, 0.0, 0.0, s])
        return -self.forces(x, np.zeros(6), d)

    # -- dynamics ----------------------------------------------------------------------------------
    def forces(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """Total generalised force at the CB, ``-C_RB nu + tau_hyd + tau_s + tau`` (N, N m),
        shape ``(..., 6)``: the right-hand side of ``M(s) nu_dot = ...``."""
        x, u, d, shape = self._flat(x, u, d)
        F, _, _ = self._features(x, u, d)
        return (self._coeffs.T @ F).T.reshape(*shape, 6)

    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        x, u, d, shape = self._flat(x, u, d)
        n = x.shape[0]
        F, trig, nu1_t = self._features(x, u, d)
        out = np.empty((13, n))
        # nu_dot = V diag(1 / (1 + s lam)) L tau_total, with L folded into GT
        y = self._GT @ F
        s = x[:, 12]
        y /= 1.0 + self._lam * s
        np.matmul(self._V, y, out=out[:6])
        # kinematics: NED velocity R nu1 = Rz Ry Rx nu1, then the Euler-angle rates
        sphi, sth, spsi, cphi, cth, cpsi = trig
        u_, v_, w_ = nu1_t
        b = cphi * v_ - sphi * w_
        c = sphi * v_ + cphi * w_
        a2 = cth * u_ + sth * c
        out[6] = cpsi * a2 - spsi * b
        out[7] = spsi * a2 + cpsi * b
        out[8] = cth * c - sth * u_
        q, r = x[:, 4], x[:, 5]
        t1 = q * sphi + r * cphi
        out[9] = x[:, 3] + t1 * (sth / cth)
        out[10] = q * cphi - r * sphi
        out[11] = t1 / cth
        out[12] = (d[:, 3] - s) * self._inv_T_m
        return out.T.reshape(*shape, 13)

    def _flat(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None):
        """x, u, d as 2-D arrays over one flattened batch, and the batch shape."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        d = np.zeros(4) if d is None else np.asarray(d, dtype=float)
        if x.ndim == 2 and u.shape == (x.shape[0], 6) and d.shape == (x.shape[0], 4) \
                and x.shape[1] == 13:
            return x, u, d, x.shape[:1]  # the vector env's hot path
        x, u, d = self._split(x, u, d)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1])
        return (np.broadcast_to(x, (*shape, 13)).reshape(-1, 13),
                np.broadcast_to(u, (*shape, 6)).reshape(-1, 6),
                np.broadcast_to(d, (*shape, 4)).reshape(-1, 4), shape)

    def _features(self, x: FloatArray, u: FloatArray, d: FloatArray):
        """Feature matrix F^T (65, n), the six trig rows, and the linear velocity rows."""
        n = x.shape[0]
        xt = x.T
        F = np.empty((_N_FEATURES, n))
        angles = xt[9:12]
        sin, cos = np.sin(angles), np.cos(angles)
        sphi, sth, spsi = sin
        cphi, cth, cpsi = cos
        nu1 = xt[:3]
        om = xt[3:6]
        current = d[:, :3]
        if current.any():
            # body-frame current R^T v_c = Rx^T Ry^T Rz^T v_c
            vn, ve, vd = current.T
            a = cpsi * vn + spsi * ve
            b = cpsi * ve - spsi * vn
            c = sth * a + cth * vd
            nur1 = np.empty((3, n))
            np.subtract(nu1[0], cth * a - sth * vd, out=nur1[0])
            np.subtract(nu1[1], cphi * b + sphi * c, out=nur1[1])
            np.subtract(nu1[2], cphi * c - sphi * b, out=nur1[2])
            F[0:3] = nur1
            F[3:6] = om
        else:
            nur1 = nu1
            F[0:6] = xt[:6]
        np.multiply(F[0:6], np.abs(F[0:6]), out=F[_ABS])
        np.multiply(nur1[0], nur1[1:3], out=F[_UV:_UW + 1])
        np.multiply(om[:, None, :], nur1[None, :, :], out=F[_OMR].reshape(3, 3, n))
        np.multiply(om[:, None, :], nu1[None, :, :], out=F[_OMN].reshape(3, 3, n))
        np.multiply(om, om, out=F[26:29])
        np.multiply(om[0], om[1:3], out=F[29:31])
        np.multiply(om[1], om[2], out=F[31])
        F[32] = sth
        np.multiply(cth, sphi, out=F[33])
        np.multiply(cth, cphi, out=F[34])
        F[_TAU] = u.T
        s = xt[12]
        for src, dst in zip(_MORPH_SRC, _MORPH_DST, strict=True):
            np.multiply(F[src], s, out=F[dst])
        return F, (sphi, sth, spsi, cphi, cth, cpsi), nu1
