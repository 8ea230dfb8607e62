"""Parameters of the morphing ROV (docs/models.md 3.3-3.5): Prestero's REMUS-100 coefficients
for the cruise shape, the [PROPOSED] work shape, and the [PROPOSED] six-thruster layout. The
equations that use them are in :mod:`marine_envs.models.rov`.

**Morph** [PROPOSED, docs/models.md 3.4]. Every quadratic coefficient that the deployed arm changes,
``r_G``, ``r_B`` and ``I_b`` are interpolated as ``theta(s) = theta_c + s (theta_w - theta_c)``;
``m``, ``W``, ``B``, the added mass and the cross-flow/lift coefficients do not change. ``s`` is
not clipped: a command outside [0, 1] extrapolates linearly. The optional +5 % added mass of the
flooded bay (docs/models.md 3.4) is not modelled.

**Actuation.** The inputs are generalised forces: an idealised, fully actuated vehicle. The
[PROPOSED] six-thruster layout of docs/models.md 3.5 (:data:`THRUSTER_ALLOCATION`, :func:`allocate`)
gives the bounds of X, Y, Z, M and N (the box of each row's reachable range; the jointly reachable
set is smaller, e.g. X and N share the stern thrusters). Its roll row is zero, so K gets a small
[PROPOSED] idealised range +-K_max; with thrusters only, roll is left to the BG pendulum.
In work shape the bow-down moment ``x_G W - x_B B = 11.3 N m`` exceeds the pitch range of the
+-10 N vertical tunnels of docs/models.md 3.5 (7.5 N m, less the 7 N buoyancy trim they also
carry), so the vertical tunnels here are rated +-25 N [PROPOSED, deviating from docs/models.md
3.5; a T200-class thruster]: the pitch range becomes +-18.75 N m and the level work-shape trim
(f5 = -11.3 N, f6 = +18.3 N) is reachable, which the morphing-robot patent reaches with its
variable-structure device.

**Stability (a property of the cited coefficients, not of this code).** Prestero's damping of
roll and pitch is quadratic, so at hover the BG pendulums (about 5.6 and 0.85 rad/s in cruise) are
undamped to first order. Under way, the Munk moments of the streamlined hull dominate: with
``Nuv < 0`` the vehicle is directionally unstable at every forward speed, and with ``Muw > 0``
pitch is unstable above 0.60 m/s (0.84 m/s in work shape; at 1.5 m/s: pitch eigenvalues
0.42 +- 0.22j 1/s, yaw divergence +1.0 1/s), while roll stays stable. REMUS flies under
autopilot; DSTO's listing adds Fodrea's revised linear coefficients (Mw = -9.3, Nv = -4.47),
which docs/models.md does not use.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from .base import FloatArray, require
from .kinematics import skew

# -- thrusters (docs/models.md 3.5, [PROPOSED]) -------------------------------------------------
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
#: Thrust limits (low, high) of each thruster, N; the vertical tunnels are stronger than the
#: +-10 N of docs/models.md 3.5 so that the work shape can be trimmed level (see the module
#: docstring).
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


def thruster_box() -> tuple[FloatArray, FloatArray]:
    """Per-row reachable range of B_T f over the thruster limits (a box, not the exact set)."""
    low, high = THRUSTER_LIMITS
    ends = np.stack([THRUSTER_ALLOCATION * low, THRUSTER_ALLOCATION * high])
    return ends.min(axis=0).sum(axis=1), ends.max(axis=0).sum(axis=1)


# -- parameters ---------------------------------------------------------------------------------
#: Quantities that the morph changes (docs/models.md 3.4); each has a ``work_<name>`` field.
MORPHING: tuple[str, ...] = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr", "Yrr", "Zqq", "Mww", "Nvv",
                             "xG", "yG", "zG", "xB", "yB", "zB", "Ixx", "Iyy", "Izz")
#: Hydrodynamic coefficients of tau_hyd, in docs/models.md 3.2 order.
HYDRO_COEFFICIENTS: tuple[str, ...] = (
    "Xuu", "Xwq", "Xqq", "Xvr", "Xrr", "Yvv", "Yrr", "Yuv", "Ywp", "Yur", "Ypq",
    "Zww", "Zqq", "Zuw", "Zvp", "Zuq", "Zrp", "Kpp", "Mww", "Mqq", "Muw", "Muq", "Mvp", "Mrp",
    "Nvv", "Nrr", "Nuv", "Nur", "Nwp", "Npq")
#: The 18 viscous coefficients that the morphing-robot patent identifies online (its order;
#: docs/models.md names).
SEED_COEFFICIENTS: tuple[str, ...] = (
    "Xuu", "Yvv", "Yuv", "Zww", "Zuw", "Yrr", "Yur", "Zqq", "Zuq", "Mww", "Muw", "Nvv", "Nuv",
    "Kpp", "Mqq", "Muq", "Nrr", "Nur")
_SHAPE = (*HYDRO_COEFFICIENTS, "xG", "yG", "zG", "xB", "yB", "zB", "Ixx", "Iyy", "Izz")
_DISSIPATIVE = ("Xuu", "Yvv", "Zww", "Kpp", "Mqq", "Nrr")
_ADDED_MASS_DIAGONAL = ("Xud", "Yvd", "Zwd", "Kpd", "Mqd", "Nrd")


@dataclasses.dataclass(frozen=True)
class ROVParams:
    """Parameters of the ROV model; names are docs/models.md's symbols (``Xuu`` = X_u|u|,
    ``Xud`` = X_u-dot). SI units, radians. Cruise values: Prestero's REMUS-100 (docs/models.md 3.3,
    [CITED] via the DSTO ``remus100_withM.m`` listing and GTRI SCRIMMAGE ``UUV6DOF.xml`` unless
    tagged); ``work_*``: the work shape's absolute values (docs/models.md 3.4 table,
    [PROPOSED])."""

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
    # combined hydrodynamic coefficients, cruise shape (docs/models.md 3.3)
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
    mS = k.m * skew(np.array([c["xG"], c["yG"], c["zG"]]))
    rigid = np.block([[k.m * np.eye(3), -mS], [mS, np.diag([c["Ixx"], c["Iyy"], c["Izz"]])]])
    return rigid + added_mass(k)


def added_mass(params: ROVParams) -> FloatArray:
    """``M_A`` (6x6, kg, kg m, kg m^2), unchanged by the morph."""
    k = params
    return -np.array([[k.Xud, 0, 0, 0, 0, 0], [0, k.Yvd, 0, 0, 0, k.Yrd],
                      [0, 0, k.Zwd, 0, k.Zqd, 0], [0, 0, 0, k.Kpd, 0, 0],
                      [0, 0, k.Mwd, 0, k.Mqd, 0], [0, k.Nvd, 0, 0, 0, k.Nrd]])
