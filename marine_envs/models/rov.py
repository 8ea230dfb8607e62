"""ROV/AUV with a morphing hull, Prestero REMUS-100 coefficients (seed 002; MODELS.md section 3).

Six-degree-of-freedom rigid body with the body origin at the centre of buoyancy (CB), SNAME/NED
axes (x forward, y starboard, z down), ZYX Euler angles. ``x = [u v w p q r  x y z  phi theta psi
s]``: body velocities nu (m/s, rad/s), NED position (m, z down), Euler angles (rad) and the morph
fraction ``s`` (0 = cruise, 1 = work shape, manipulator deployed at the bow). ``u = tau = [X Y Z K
M N]``: generalised forces at the CB (N, N m). ``d = [current_n current_e current_d s_cmd]``: a
constant, irrotational ocean current in NED (m/s) and the morph command (-). MODELS.md 3.2::

    (M_RB(s) + M_A) nu_dot = -C_RB(nu, s) nu + tau_hyd(nu_r, s) + tau_s(eta, s) + tau
                             - M_A [w x nu_c; 0]          (current only, see "Current")
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

**Current.** ``nu_r = nu - [nu_c; 0 0 0]``, ``nu_c = R(eta)^T v_c`` with ``v_c`` the NED current,
assumed constant and irrotational. The hydrodynamic terms act on the velocity through the water
``nu_r``; the rigid-body terms and the kinematics on ``nu`` (velocity over ground). The added-mass
inertia accelerates the water-relative motion, ``M_A nu_r_dot = M_A nu_dot + M_A [w x nu_c; 0]``
(``nu_c_dot = -w x nu_c``), which is Fossen's relative-velocity form, exact for such a current
(``current_inertia="relative"``, the default). The simpler approximation ``M_A nu_dot``
(``current_inertia="ground"``) drops the force ``-M_A [w x nu_c; 0]``; it is not energy-consistent:
a drifting boat that turns in the current gains relative speed again instead of settling.

**Morph** [PROPOSED, MODELS.md 3.4]. Every quadratic coefficient that the deployed arm changes,
``r_G``, ``r_B`` and ``I_b`` are interpolated as ``theta(s) = theta_c + s (theta_w - theta_c)``;
``m``, ``W``, ``B``, the added mass and the cross-flow/lift coefficients do not change. ``s`` is
not clipped: a command outside [0, 1] extrapolates linearly. The optional +5 % added mass of the
flooded bay (MODELS.md 3.4) is not modelled.

**Actuation.** The inputs are generalised forces: an idealised, fully actuated vehicle. The
[PROPOSED] six-thruster layout of MODELS.md 3.5 (:data:`THRUSTER_ALLOCATION`, :func:`allocate`)
gives the bounds of X, Y, Z, M and N (the box of each row's reachable range; the jointly reachable
set is smaller, e.g. X and N share the stern thrusters). Its roll row is zero, so K gets a small
[PROPOSED] idealised range +-K_max; with thrusters only, roll is left to the BG pendulum.
In work shape the bow-down moment ``x_G W - x_B B = 11.3 N m`` exceeds the pitch range of
MODELS.md's +-10 N vertical tunnels (7.5 N m, less the 7 N buoyancy trim they also carry), so the
vertical tunnels here are rated +-25 N [PROPOSED, deviating from MODELS.md 3.5; a T200-class
thruster]: the pitch range becomes +-18.75 N m and the level work-shape trim (f5 = -11.3 N,
f6 = +18.3 N) is reachable, which the seed reaches with its variable-structure device.

**Stability (a property of the cited coefficients, not of this code).** Prestero's damping of
roll and pitch is quadratic, so at hover the BG pendulums (about 5.6 and 0.85 rad/s in cruise) are
undamped to first order. Under way, the Munk moments of the streamlined hull dominate: with
``Nuv < 0`` the vehicle is directionally unstable at every forward speed, and with ``Muw > 0``
pitch is unstable above 0.60 m/s (0.84 m/s in work shape; at 1.5 m/s: pitch eigenvalues
0.42 +- 0.22j 1/s, yaw divergence +1.0 1/s), while roll stays stable. REMUS flies under
autopilot; DSTO's listing adds Fodrea's revised linear coefficients (Mw = -9.3, Nv = -4.47),
which MODELS.md does not use.

**Implementation.** ``rhs`` is written for batches (one contiguous row per state): the forces are
linear in a feature matrix ``F`` of products (``u|u|``, ``w q``, ``sin(theta)``, ``tau``, ...),
``tau_total = C_0^T F + s dC^T F_morph``. ``M(s) = M_0 + s dM`` is inverted exactly for every
``s`` through the generalised eigen-decomposition ``dM V = M_0 V diag(lam)``, ``V^T M_0 V = I``:
``M(s)^-1 = V diag(1 / (1 + s lam)) V^T``. With ``V^T`` folded into the coefficients, ``nu_dot``
costs one (12 x 41) GEMM, a scaling and a 6x6 product (one 6-row GEMM with ``M_0^-1`` folded in
when the whole batch is in cruise shape). Without a current the hydrodynamic and rigid-body
``omega nu`` products coincide and are folded together. A single boat takes a path on Python
floats with the same feature layout.

**Identification** (seed 002). :data:`SEED_COEFFICIENTS` are the 18 viscous coefficients the seed
identifies online. ``tau_hyd`` is linear in every coefficient:
:meth:`ROVModel.hydrodynamic_regressors` gives its exact regressor ``Phi``;
:meth:`ROVModel.rhs_with` takes a coefficient's value AT THE CURRENT SHAPE (what an online
identifier sees) and is ``rhs(x, u + Phi (theta - c(s)), d)``;
:meth:`ROVModel.parameter_jacobian` is the exact ``[M(s)^-1 Phi; 0]``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
from collections.abc import Mapping, Sequence
from typing import ClassVar, Literal

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

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
    THRUSTER_DIRECTIONS.T, np.cross(THRUSTER_POSITIONS, THRUSTER_DIRECTIONS).T]) + 0.0  # no -0
#: Thrust limits (low, high) of each thruster, N; the vertical tunnels are stronger than MODELS.md's
#: +-10 N so that the work shape can be trimmed level (see the module docstring).
THRUSTER_LIMITS: tuple[FloatArray, FloatArray] = (
    np.array([-20.0, -20.0, -10.0, -10.0, -25.0, -25.0]),
    np.array([30.0, 30.0, 10.0, 10.0, 25.0, 25.0]))
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
#: The 18 viscous coefficients that seed 002 identifies online (its order; MODELS.md names).
SEED_COEFFICIENTS: tuple[str, ...] = (
    "Xuu", "Yvv", "Yuv", "Zww", "Zuw", "Yrr", "Yur", "Zqq", "Zuq", "Mww", "Muw", "Nvv", "Nuv",
    "Kpp", "Mqq", "Muq", "Nrr", "Nur")
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
    #: water density, kg/m^3 [CITED]; for the record only: the coefficients are dimensional
    rho: float = 1030.0
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
    #: What the added-mass inertia accelerates in a current (see the module docstring):
    #: "relative" (nu_r_dot, Fossen's exact form for a constant irrotational current) or
    #: "ground" (nu_dot, the simpler approximation).
    current_inertia: Literal["relative", "ground"] = "relative"

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "current_inertia":
                require(value in ("relative", "ground"), f.name, value,
                        "must be 'relative' or 'ground'")
                continue
            require(isinstance(value, numbers.Real) and not isinstance(value, bool)
                    and math.isfinite(value), f.name, value, "must be a finite number")
        positive = ("m", "W", "B", "rho", "T_m", "K_max", "Ixx", "Iyy", "Izz",
                    "work_Ixx", "work_Iyy", "work_Izz")
        for name in positive:
            require(getattr(self, name) > 0, name, getattr(self, name), "must be > 0")
        for name in (*_DISSIPATIVE, *(f"work_{n}" for n in _DISSIPATIVE), *_ADDED_MASS_DIAGONAL):
            require(getattr(self, name) <= 0, name, getattr(self, name),
                    "must be <= 0 (dissipative damping / positive added mass)")
        for s in (0.0, 1.0):  # M(s) is affine in s: positive definite at both ends suffices
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
    return rigid + added_mass(k)


def added_mass(params: ROVParams) -> FloatArray:
    """``M_A`` (6x6, kg, kg m, kg m^2), unchanged by the morph."""
    k = params
    return -np.array([[k.Xud, 0, 0, 0, 0, 0], [0, k.Yvd, 0, 0, 0, k.Yrd],
                      [0, 0, k.Zwd, 0, k.Zqd, 0], [0, 0, 0, k.Kpd, 0, 0],
                      [0, 0, k.Mwd, 0, k.Mqd, 0], [0, k.Nvd, 0, 0, 0, k.Nrd]])


def _skew(a: FloatArray) -> FloatArray:
    """S(a) with S(a) b = a x b."""
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def _cross_map() -> FloatArray:
    """(9, 3) map from the products ``a_i b_j`` (row 3 i + j) to ``a x b``."""
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    return eps.transpose(1, 2, 0).reshape(9, 3)


_CROSS = _cross_map()


# -- feature layout of the batched right-hand side (rows of F, one column per boat) ------------
_OMR = slice(0, 9)  # omega_i nu_r_j at row 3 i + j (i: p q r; j: u v w): hydrodynamic
_UV, _UW = 9, 10  # u_r v_r, u_r w_r
_TAU = slice(11, 17)  # X Y Z K M N
_ABS = slice(17, 23)  # u_r|u_r|, v_r|v_r|, w_r|w_r|, p|p|, q|q|, r|r|
_OMN = slice(23, 32)  # omega_i nu_j at row 23 + 3 i + j: rigid-body Coriolis, over ground
_ANG = slice(32, 38)  # p p, q q, r r, p q, p r, q r
_RES = slice(38, 41)  # sin(theta), cos(theta) sin(phi), cos(theta) cos(phi)
_MORPH = slice(17, 41)  # features whose coefficients change with s
_STILL = slice(9, 41)  # features used in still water, where omega nu_r = omega nu (OMR folded)
_N_FEATURES = 41
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
_X, _Y, _Z, _K, _M, _N = range(6)
_AB, _AN = _ABS.start, _ANG.start
#: coefficient -> (feature row of F, force component) of its single term in tau_hyd
_HYDRO_ENTRIES: dict[str, tuple[int, int]] = {
    "Xuu": (_AB, _X), "Yvv": (_AB + 1, _Y), "Nvv": (_AB + 1, _N), "Zww": (_AB + 2, _Z),
    "Mww": (_AB + 2, _M), "Kpp": (_AB + 3, _K), "Zqq": (_AB + 4, _Z), "Mqq": (_AB + 4, _M),
    "Yrr": (_AB + 5, _Y), "Nrr": (_AB + 5, _N),
    "Yuv": (_UV, _Y), "Nuv": (_UV, _N), "Zuw": (_UW, _Z), "Muw": (_UW, _M),
    "Zvp": (1, _Z), "Mvp": (1, _M), "Ywp": (2, _Y), "Nwp": (2, _N),  # p v_r, p w_r
    "Zuq": (3, _Z), "Muq": (3, _M), "Xwq": (5, _X),  # q u_r, q w_r
    "Yur": (6, _Y), "Nur": (6, _N), "Xvr": (7, _X),  # r u_r, r v_r
    "Xqq": (_AN + 1, _X), "Xrr": (_AN + 2, _X), "Ypq": (_AN + 3, _Y), "Npq": (_AN + 3, _N),
    "Zrp": (_AN + 4, _Z), "Mrp": (_AN + 4, _M),
}


def _coefficient_matrix(k: ROVParams, c: dict[str, float]) -> FloatArray:
    """(41, 6) matrix C with tau_total = C^T F for the shape ``c`` (affine in ``c``)."""
    C = np.zeros((_N_FEATURES, 6))
    ang = _ANG.start
    for name, (row, col) in _HYDRO_ENTRIES.items():
        C[row, col] = c[name]
    # rigid-body Coriolis, part linear in nu1: a = omega x nu1
    r_G = np.array([c["xG"], c["yG"], c["zG"]])
    C[_OMN, :3] = -k.m * _CROSS  # -m omega x nu1
    C[_OMN, 3:] = -k.m * _CROSS @ _skew(r_G).T  # -m r_G x (omega x nu1)
    # rigid-body Coriolis, part quadratic in omega: split exactly into the monomials of _ANG
    inertia = np.array([c["Ixx"], c["Iyy"], c["Izz"]])

    def quad(om: FloatArray) -> FloatArray:
        return np.concatenate([-k.m * np.cross(om, np.cross(om, r_G)),
                               -np.cross(om, inertia * om)])

    unit = np.eye(3)
    for row, (i, j) in enumerate(_PAIRS, start=ang):
        C[row] += quad(unit[i]) if i == j else \
            quad(unit[i] + unit[j]) - quad(unit[i]) - quad(unit[j])
    # restoring forces, g = r_G W - r_B B
    wb = k.W - k.B
    gx, gy, gz = r_G * k.W - np.array([c["xB"], c["yB"], c["zB"]]) * k.B
    res = _RES.start
    C[res, [_X, _M, _N]] = -wb, -gz, gy
    C[res + 1, [_Y, _K, _N]] = wb, -gz, gx
    C[res + 2, [_Z, _K, _M]] = wb, gy, -gx
    C[_TAU] = np.eye(6)
    return C


def _shape_free(hydro: Mapping[str, ArrayLike],
                other: Mapping[str, ArrayLike]) -> dict[str, ArrayLike]:
    """Parameters for the generic ``rhs_with``: a coefficient's value at the current shape is
    the same cruise and work value (then ``c(s)`` is that value for every ``s``)."""
    clash = [f"work_{n}" for n in hydro if f"work_{n}" in other]
    if clash:
        raise ValueError(f"params give both {clash} and the coefficient at the current shape; "
                         "give one of them")
    both = dict(other)
    for name, value in hydro.items():
        both[name] = value
        if name in MORPHING:
            both[f"work_{name}"] = value
    return both


def _feature_factors(row: int) -> tuple[int, int]:
    """The two factors of feature row ``row`` as indices into ``[u_r v_r w_r p q r]``; a
    second factor of -1 means ``|first|`` (the ``a|a|`` features)."""
    if row < _OMR.stop:
        return 3 + row // 3, row % 3  # omega_i nu_r_j
    if row in (_UV, _UW):
        return 0, row - _UV + 1
    if _ABS.start <= row < _ABS.stop:
        return row - _ABS.start, -1
    i, j = _PAIRS[row - _ANG.start]
    return 3 + i, 3 + j


@functools.lru_cache(maxsize=64)
def _hydro_layout(names: tuple[str, ...]):
    """``(first, second, absolute, select)`` of the coefficients ``names``: factor indices of
    each feature, which are ``a|a|``, and the (p, 6) map from terms to force rows."""
    unknown = [n for n in names if n not in _HYDRO_ENTRIES]
    if unknown:
        raise ValueError(f"unknown hydrodynamic coefficient(s) {unknown}; known: "
                         f"{', '.join(HYDRO_COEFFICIENTS)}")
    factors = np.array([_feature_factors(_HYDRO_ENTRIES[n][0]) for n in names],
                       dtype=np.intp).reshape(-1, 2)
    absolute = factors[:, 1] < 0
    second = np.where(absolute, factors[:, 0], factors[:, 1])
    select = np.zeros((len(names), 6))
    select[np.arange(len(names)), [_HYDRO_ENTRIES[n][1] for n in names]] = 1.0
    return factors[:, 0], second, absolute, select


def _hydro_features(motion: FloatArray, first: NDArray[np.intp], second: NDArray[np.intp],
                    absolute: NDArray[np.bool_]) -> FloatArray:
    """Features (n, p) of the coefficients from the water-relative motion (n, 6)."""
    other = motion[:, second]
    if absolute.any():
        other[:, absolute] = np.abs(other[:, absolute])
    return motion[:, first] * other


def _relative_motion(x: FloatArray, d: FloatArray) -> FloatArray:
    """``[u_r v_r w_r p q r]`` (n, 6) of flat states (n, 13) in the NED current of ``d``: the
    body velocity minus ``R(eta)^T v_c``."""
    motion = x[:, :6].copy()
    current = d[:, :3]
    if not current.any():
        return motion
    sphi, sth, spsi = np.sin(x[:, 9:12]).T
    cphi, cth, cpsi = np.cos(x[:, 9:12]).T
    vn, ve, vd = current.T
    a = cpsi * vn + spsi * ve
    b = cpsi * ve - spsi * vn
    c = sth * a + cth * vd
    motion[:, 0] -= cth * a - sth * vd
    motion[:, 1] -= cphi * b + sphi * c
    motion[:, 2] -= cphi * c - sphi * b
    return motion


class ROVModel(VehicleModel):
    """REMUS-100-type AUV/ROV with a cruise/work morphing hull (seed 002; MODELS.md 3).

    :param params: the parameters; ``None`` = nominal (Prestero's REMUS-100 cruise shape and the
        [PROPOSED] work shape of MODELS.md 3.4).
    """

    name: ClassVar[str] = "rov"
    state_names: ClassVar[tuple[str, ...]] = (
        "u", "v", "w", "p", "q", "r", "x", "y", "z", "phi", "theta", "psi", "s")
    input_names: ClassVar[tuple[str, ...]] = ("X", "Y", "Z", "K", "M", "N")
    disturbance_names: ClassVar[tuple[str, ...]] = ("current_n", "current_e", "current_d", "s_cmd")
    state_units: ClassVar[tuple[str, ...]] = (
        "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s", "m", "m", "m", "rad", "rad", "rad", "-")
    input_units: ClassVar[tuple[str, ...]] = ("N", "N", "N", "N m", "N m", "N m")
    disturbance_units: ClassVar[tuple[str, ...]] = ("m/s", "m/s", "m/s", "-")
    #: Nominal point: REMUS cruise speed, m/s, and depth, m.
    cruise_speed: ClassVar[float] = 1.5
    cruise_depth: ClassVar[float] = 5.0

    def __init__(self, params: ROVParams | None = None) -> None:
        super().__init__(ROVParams() if params is None else params)
        k = self.params
        C0 = _coefficient_matrix(k, k.shape_at(0.0))
        dC = _coefficient_matrix(k, k.shape_at(1.0)) - C0
        if dC[:_MORPH.start].any():
            raise AssertionError("a morphing coefficient outside the morph features")
        still = C0[_STILL].copy()
        still[_OMN.start - _STILL.start:_OMN.stop - _STILL.start] += C0[_OMR]
        C0_cur = C0.copy()
        if k.current_inertia == "relative":
            # M_A nu_r_dot = M_A nu_dot + M_A [omega x nu_c; 0]: move the second term to the
            # right; omega_i nu_c_j = F[_OMN] - F[_OMR], so it is linear in the features
            term = _CROSS @ -added_mass(k)[:, :3].T
            C0_cur[_OMN] += term
            C0_cur[_OMR] -= term
        # tau_total = C0^T F + s dC^T F[_MORPH]   (forces(); trim)
        self._C0T, self._dCT = C0_cur.T.copy(), dC[_MORPH].T.copy()
        # M(s) = M0 + s dM = L^-1 diag(1 + s lam) V^-1, so M(s)^-1 = V diag(1 / (1 + s lam)) L
        M0 = mass_matrix(k, 0.0)
        dM = mass_matrix(k, 1.0) - M0
        if np.array_equal(M0, M0.T) and np.array_equal(dM, dM.T):
            lam, V = scipy.linalg.eigh(dM, M0)  # V^T M0 V = I, V^T dM V = diag(lam)
            L = V.T
        else:  # non-symmetric added mass (Yrd != Nvd or Zqd != Mwd): general eigenproblem
            lam, V = np.linalg.eig(np.linalg.solve(M0, dM))
            require(bool(np.all(np.abs(lam.imag) < 1e-9 * (1 + np.abs(lam.real))))
                    and np.linalg.cond(V) < 1e8, "added mass (Yrd, Nvd, Zqd, Mwd)",
                    (k.Yrd, k.Nvd, k.Zqd, k.Mwd),
                    "too far from symmetric for the exact morph inverse")
            lam, V = lam.real, V.real
            L = np.linalg.solve(V, np.linalg.inv(M0))
        self._lam, self._lam_col, self._V = lam, lam[:, None].copy(), np.ascontiguousarray(V)
        self._L = np.ascontiguousarray(L)
        # nu_dot = V (A F + s B F[_MORPH]) / (1 + s lam); with s = 0 everywhere: nu_dot = P F
        self._A_cur, self._A_still = L @ C0_cur.T, L @ still.T
        self._B = L @ dC[_MORPH].T
        self._P_cur, self._P_still = V @ self._A_cur, V @ self._A_still
        # [A; B] stacked over the features in use: one GEMM for both (B padded with zeros)
        self._AB_cur = np.zeros((12, _N_FEATURES))
        self._AB_cur[:6], self._AB_cur[6:, _MORPH] = self._A_cur, self._B
        self._AB_still = self._AB_cur[:, _STILL].copy()
        self._AB_still[:6] = self._A_still
        self._inv_T_m = 1.0 / k.T_m
        self._x0 = np.zeros(len(self.state_names))
        self._x0[[0, 8]] = self.cruise_speed, self.cruise_depth
        self._u0 = self.trim_forces(self.cruise_speed, 0.0)
        low, high = _thruster_box()
        low[_K], high[_K] = -k.K_max, k.K_max
        self._u_bounds = (low, high)

    # -- nominal point, bounds, shape ---------------------------------------------------------
    @property
    def x0(self) -> FloatArray:
        """Cruise at ``u = 1.5 m/s``, depth 5 m, level, heading north, cruise shape (s = 0)."""
        return self._x0.copy()

    @property
    def u0(self) -> FloatArray:
        """Generalised forces holding :attr:`x0` at zero acceleration (``x`` still grows at
        1.5 m/s): surge thrust against the drag, heave force against the net buoyancy."""
        return self._u0.copy()

    @property
    def u_bounds(self) -> tuple[FloatArray, FloatArray]:
        """Box of the thruster layout's reachable range per row (X [-40, 60] N, Y and Z +-20 N,
        M +-18.75 N m, N +-13.5 N m) and the idealised roll moment +-K_max."""
        return self._u_bounds[0].copy(), self._u_bounds[1].copy()

    def coefficients(self, s: float) -> dict[str, float]:
        """Interpolated coefficients, r_G, r_B (m) and I_b (kg m^2) at morph fraction ``s``
        (:meth:`ROVParams.shape_at`)."""
        return self.params.shape_at(s)

    def mass_matrix(self, s: float = 0.0) -> FloatArray:
        """``M_RB(s) + M_A`` (6x6) at morph fraction ``s``."""
        return mass_matrix(self.params, s)

    def trim_forces(self, u_speed: float, s: float = 0.0) -> FloatArray:
        """Generalised forces (N, N m) that hold steady, level, straight motion at surge speed
        ``u_speed`` (m/s) in still water with the hull held at shape ``s`` (``s_cmd = s``):
        ``X = -Xuu(s) u|u|``, ``Z = -(W - B)``, ``M = x_G W - x_B B`` (interpolated)."""
        x = np.zeros(len(self.state_names))
        x[[0, 8, 12]] = u_speed, self.cruise_depth, s
        return 0.0 - self.forces(x, np.zeros(6), np.array([0.0, 0.0, 0.0, s]))  # no -0.0

    # -- dynamics ------------------------------------------------------------------------------
    def forces(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        """Total generalised force at the CB, ``-C_RB nu + tau_hyd + tau_s + tau`` (N, N m),
        shape ``(..., 6)``: the right-hand side of ``M(s) nu_dot = ...``."""
        x, u, d, shape = self._flat(x, u, d)
        xt = np.ascontiguousarray(x.T)
        F, _, _ = self._features(xt, u, d, full=True)
        tau = self._C0T @ F + xt[12] * (self._dCT @ F[_MORPH])
        return tau.T.reshape(*shape, 6)

    def hydrodynamic_regressors(self, x: ArrayLike, names: Sequence[str],
                                d: ArrayLike | None = None) -> FloatArray:
        """``d tau_hyd / d theta``: the feature of each coefficient (e.g. ``u_r|u_r|`` for ``Xuu``,
        on the velocity through the water) in its force row, zero elsewhere. ``tau_hyd`` is linear
        in the coefficients, so this is exact: ``tau_hyd = regressors @ theta``.

        :param x: states, shape ``(..., 13)``.
        :param names: coefficients, each one of :data:`HYDRO_COEFFICIENTS` (``p`` of them).
        :param d: disturbances (current, m/s; morph command), shape ``(..., 4)``; None = zero.
        :return: shape ``(..., 6, p)``; force rows N or N m per coefficient unit.
        """
        first, second, absolute, select = _hydro_layout(tuple(names))
        x, _, d, shape = self._flat(x, np.zeros(6), d)
        features = _hydro_features(_relative_motion(x, d), first, second, absolute)
        out = features[:, None, :] * select.T[None]
        return out.reshape(*shape, 6, len(first))

    def rhs_with(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                 params: Mapping[str, ArrayLike]) -> FloatArray:
        """:meth:`rhs` with parameters replaced per batch row.

        A hydrodynamic coefficient (one of :data:`HYDRO_COEFFICIENTS`) gives its value AT THE
        CURRENT SHAPE ``s``: it replaces the interpolated ``c(s)``, so that an identifier
        estimates what the hull has now. ``tau_hyd`` is linear in the coefficients and ``tau``
        enters beside it, so this is exactly ``rhs(x, u + Phi (theta - c(s)), d)`` =
        ``rhs + [M(s)^-1 Phi (theta - c(s)); 0]`` with ``Phi`` = :meth:`hydrodynamic_regressors`:
        the model's exact ``M(s)^-1`` at the cost of one ``rhs``. Other names (``m``,
        ``work_Xuu``, ...) go to the generic path of :meth:`VehicleModel.rhs_with`; mixed with
        coefficients, each coefficient is passed there as its cruise AND work value (same
        meaning, slower).

        :param x, u, d: as :meth:`rhs`.
        :param params: ``{name: value}``, each a scalar or an array broadcasting with the batch
            shape (e.g. ``(N,)`` for ``x`` of shape ``(N, 13)``), in the parameter's unit.
        :return: ``x_dot``, shape ``(..., 13)`` over the broadcast batch shape.
        """
        hydro = {k: v for k, v in params.items() if k in _HYDRO_ENTRIES}
        if not hydro:
            return super().rhs_with(x, u, d, params)
        if len(hydro) < len(params):
            other = {k: v for k, v in params.items() if k not in _HYDRO_ENTRIES}
            return super().rhs_with(x, u, d, _shape_free(hydro, other))
        x, u, d, theta, shape = self._batch_with(x, u, d, list(hydro.values()))
        first, second, absolute, select = _hydro_layout(tuple(hydro))
        cruise, change = self._morph_line(tuple(hydro))
        features = _hydro_features(_relative_motion(x, d), first, second, absolute)
        features *= theta - (cruise + x[:, 12:13] * change)
        return self.rhs(x, u + features @ select, d).reshape(*shape, 13)

    def parameter_jacobian(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                           params: Mapping[str, ArrayLike]) -> FloatArray | None:
        """``d rhs_with / d params``, shape ``(..., 13, p)`` in the order of ``params``: exact
        ``[M(s)^-1 Phi; 0]`` when every name is a hydrodynamic coefficient (``rhs_with`` is
        linear in them, so the values themselves do not matter), else the base class's answer.
        """
        if not params or not set(params) <= _HYDRO_ENTRIES.keys():
            return super().parameter_jacobian(x, u, d, params)
        x, _, d, _, shape = self._batch_with(x, u, d, list(params.values()))
        first, second, absolute, select = _hydro_layout(tuple(params))
        features = _hydro_features(_relative_motion(x, d), first, second, absolute)
        phi = features[:, None, :] * select.T[None]  # (n, 6, p)
        # M(s)^-1 = V diag(1 / (1 + s lam)) L, exact for every s
        scaled = (self._L @ phi) / (1.0 + x[:, 12, None, None] * self._lam[:, None])
        out = np.zeros((x.shape[0], 13, len(first)))
        out[:, :6] = self._V @ scaled
        return out.reshape(*shape, 13, len(first))

    def _batch_with(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None,
                    values: list[ArrayLike]):
        """Flat ``x, u, d`` and the parameter matrix ``theta`` (n, p) over the broadcast batch
        shape of the arrays and the parameter values, and that shape."""
        x, u, d = self._split(x, u, d)
        arrays = [np.asarray(v, dtype=float) for v in values]
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1],
                                    *(a.shape for a in arrays))
        size = math.prod(shape)
        x, u, d = (a.reshape(-1, a.shape[-1]) if a.shape[:-1] == shape else
                   np.broadcast_to(a, (*shape, a.shape[-1])).reshape(-1, a.shape[-1])
                   for a in (x, u, d))
        theta = np.empty((size, len(arrays)))
        for j, a in enumerate(arrays):
            theta[:, j] = a.reshape(-1) if a.shape == shape else np.broadcast_to(a, shape).ravel()
        return x, u, d, theta, shape

    def _morph_line(self, names: tuple[str, ...]) -> tuple[FloatArray, FloatArray]:
        """Cruise values and work-minus-cruise changes of ``names``: ``c(s) = c_0 + s dc``."""
        k = self.params
        cruise = np.array([getattr(k, n) for n in names])
        change = np.array([getattr(k, f"work_{n}") - getattr(k, n) if n in MORPHING else 0.0
                           for n in names])
        return cruise, change

    def rhs(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None = None) -> FloatArray:
        x, u, d, shape = self._flat(x, u, d)
        if x.shape[0] == 1:  # single boat: Python floats beat numpy's per-call overhead
            return self._rhs_one(x[0], u[0], d[0]).reshape(*shape, 13)
        xt = np.ascontiguousarray(x.T)  # one row per state: contiguous rows for every op
        F, (sin, cos), current = self._features(xt, u, d)
        out = np.empty((13, xt.shape[1]))
        s = xt[12]
        used = F if current else F[_STILL]
        if s.any():
            Y = (self._AB_cur if current else self._AB_still) @ used
            y = Y[:6]
            y += np.multiply(Y[6:], s, out=Y[6:])
            y /= 1.0 + self._lam_col * s
            np.matmul(self._V, y, out=out[:6])
        else:  # the whole batch in cruise shape: M0^-1 is folded into one matrix
            np.matmul(self._P_cur if current else self._P_still, used, out=out[:6])
        # kinematics: NED velocity R nu1 = Rz Ry Rx nu1, then the Euler-angle rates
        sphi, sth, spsi = sin
        cphi, cth, cpsi = cos
        u_, v_, w_, p_, q_, r_ = xt[:6]
        b = cphi * v_ - sphi * w_
        c = sphi * v_ + cphi * w_
        a = cth * u_ + sth * c
        out[6] = cpsi * a - spsi * b
        out[7] = spsi * a + cpsi * b
        out[8] = cth * c - sth * u_
        t1 = q_ * sphi + r_ * cphi
        sec = 1.0 / cth
        out[9] = p_ + t1 * sth * sec
        out[10] = q_ * cphi - r_ * sphi
        np.multiply(t1, sec, out=out[11])
        np.subtract(d[:, 3], s, out=out[12])
        out[12] *= self._inv_T_m
        return out.T.reshape(*shape, 13)

    def _flat(self, x: ArrayLike, u: ArrayLike, d: ArrayLike | None):
        """x, u, d as 2-D arrays over one flattened batch, and the batch shape."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        d = np.zeros(4) if d is None else np.asarray(d, dtype=float)
        if x.ndim == 2 and x.shape[1] == 13 and u.shape == (x.shape[0], 6) \
                and d.shape == (x.shape[0], 4):
            return x, u, d, x.shape[:1]  # the vector environment's hot path
        if x.shape == (13,) and u.shape == (6,) and d.shape == (4,):
            return x[None], u[None], d[None], ()  # one boat
        x, u, d = self._split(x, u, d)
        shape = np.broadcast_shapes(x.shape[:-1], u.shape[:-1], d.shape[:-1])
        return (np.broadcast_to(x, (*shape, 13)).reshape(-1, 13),
                np.broadcast_to(u, (*shape, 6)).reshape(-1, 6),
                np.broadcast_to(d, (*shape, 4)).reshape(-1, 4), shape)

    def _features(self, xt: FloatArray, u: FloatArray, d: FloatArray, full: bool = False):
        """Feature matrix F (41, n) from the state rows ``xt`` (13, n), the Euler angles' sines
        and cosines (3, n) each, and whether a current is present. Without a current (and
        ``full`` False) the rows ``_OMR`` are left unset: ``_STILL`` folds them into ``_OMN``."""
        n = xt.shape[1]
        F = np.empty((_N_FEATURES, n))
        # sin and cos from one tan, t = tan(a/2): sin = 2t/(1+t^2), cos = 2/(1+t^2) - 1
        # (cheaper than np.sin + np.cos, within a few ulp of them)
        t = np.tan(0.5 * xt[9:12])
        two_den = np.multiply(t, t)
        two_den += 1.0
        np.divide(2.0, two_den, out=two_den)
        sin = t * two_den
        cos = np.subtract(two_den, 1.0, out=two_den)
        sphi, sth, spsi = sin
        cphi, cth, cpsi = cos
        nu1, om = xt[0:3], xt[3:6]
        cur = d[:, :3]
        current = bool(cur.any())
        if current:
            vn, ve, vd = cur.T  # body-frame current R^T v_c = Rx^T Ry^T Rz^T v_c
            a = cpsi * vn + spsi * ve
            b = cpsi * ve - spsi * vn
            c = sth * a + cth * vd
            nur = F[_ABS]  # u_r v_r w_r p q r, squared in place once the products are taken
            np.subtract(nu1[0], cth * a - sth * vd, out=nur[0])
            np.subtract(nu1[1], cphi * b + sphi * c, out=nur[1])
            np.subtract(nu1[2], cphi * c - sphi * b, out=nur[2])
            nur[3:] = om
            nur1 = nur[:3]
        else:
            nur, nur1 = xt[:6], nu1
        if current or full:
            np.multiply(om[:, None, :], nur1[None, :, :], out=F[_OMR].reshape(3, 3, n))
        np.multiply(nur1[0], nur1[1:3], out=F[_UV:_UW + 1])
        np.multiply(nur, np.abs(nur), out=F[_ABS])
        np.multiply(om[:, None, :], nu1[None, :, :], out=F[_OMN].reshape(3, 3, n))
        ang = _ANG.start
        np.multiply(om, om, out=F[ang:ang + 3])
        np.multiply(om[0], om[1:3], out=F[ang + 3:ang + 5])
        np.multiply(om[1], om[2], out=F[ang + 5])
        F[_RES.start] = sth
        np.multiply(cth, sin[0], out=F[_RES.start + 1])
        np.multiply(cth, cphi, out=F[_RES.start + 2])
        F[_TAU] = u.T
        return F, (sin, cos), current

    def _rhs_one(self, x: FloatArray, u: FloatArray, d: FloatArray) -> FloatArray:
        """:meth:`rhs` of one boat on Python floats (same equations and feature layout)."""
        u_, v, w, p, q, r, _, _, _, phi, theta, psi, s = x.tolist()
        vn, ve, vd, s_cmd = d.tolist()
        sphi, cphi = math.sin(phi), math.cos(phi)
        sth, cth = math.sin(theta), math.cos(theta)
        spsi, cpsi = math.sin(psi), math.cos(psi)
        if vn or ve or vd:
            a = cpsi * vn + spsi * ve
            b = cpsi * ve - spsi * vn
            c = sth * a + cth * vd
            ur, vr, wr = u_ - (cth * a - sth * vd), v - (cphi * b + sphi * c), \
                w - (cphi * c - sphi * b)
            f = [p * ur, p * vr, p * wr, q * ur, q * vr, q * wr, r * ur, r * vr, r * wr]
            A, P = self._A_cur, self._P_cur
        else:
            ur, vr, wr = u_, v, w
            f = []
            A, P = self._A_still, self._P_still
        f += [ur * vr, ur * wr, *u.tolist(),
              ur * abs(ur), vr * abs(vr), wr * abs(wr), p * abs(p), q * abs(q), r * abs(r),
              p * u_, p * v, p * w, q * u_, q * v, q * w, r * u_, r * v, r * w,
              p * p, q * q, r * r, p * q, p * r, q * r, sth, cth * sphi, cth * cphi]
        out = np.empty(13)
        feats = np.array(f)
        if s:
            y = A @ feats + s * (self._B @ feats[-24:])
            y /= 1.0 + s * self._lam
            out[:6] = self._V @ y
        else:
            out[:6] = P @ feats
        b = cphi * v - sphi * w
        c = sphi * v + cphi * w
        a = cth * u_ + sth * c
        t1 = q * sphi + r * cphi
        out[6:] = (cpsi * a - spsi * b, spsi * a + cpsi * b, cth * c - sth * u_,
                   p + t1 * sth / cth, q * cphi - r * sphi, t1 / cth, (s_cmd - s) * self._inv_T_m)
        return out
