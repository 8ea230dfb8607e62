"""Rigid-body kinematics, written once for every vehicle (Fossen's ``Rzyx``/``Tzyx``/``Smtrx``).

Axes are SNAME/NED: body x forward, y starboard, z down; ZYX Euler angles ``(phi, theta, psi)``
(roll, pitch, yaw, rad). The matrices serve users and tests; the models' right-hand sides call
the component forms, compiled (:mod:`marine_envs.compiled`), which take the angles' sines and
cosines once computed and return one value per component: scalars inside a compiled model, or
arrays (a batch's rows) from Python.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..compiled import jit
from .base import FloatArray

#: ``(sin phi, sin theta, sin psi)`` or the cosines: scalars or arrays of one shape each.
Trig = tuple[ArrayLike, ArrayLike, ArrayLike]


# -- matrices ------------------------------------------------------------------------------------
def skew(a: ArrayLike) -> FloatArray:
    """``S(a)`` (3x3) with ``S(a) b = a x b`` (Fossen's ``Smtrx``)."""
    a = np.asarray(a, dtype=float)
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def Rzyx(phi: float, theta: float, psi: float) -> FloatArray:
    """Rotation from body to NED axes (3x3): ``v_ned = Rzyx v_body``."""
    return np.array(body_to_ned(_sines(phi, theta, psi), _cosines(phi, theta, psi),
                                       *np.eye(3)))


def Tzyx(phi: float, theta: float) -> FloatArray:
    """Map from body angular rates ``[p q r]`` to Euler-angle rates (3x3); singular at
    ``theta = +-pi/2``."""
    return np.array(euler_rates(_sines(phi, theta, 0.0), _cosines(phi, theta, 0.0),
                                       *np.eye(3)))


def _sines(*angles: float) -> tuple[float, ...]:
    return tuple(math.sin(a) for a in angles)


def _cosines(*angles: float) -> tuple[float, ...]:
    return tuple(math.cos(a) for a in angles)


# -- component forms (6 DOF) ---------------------------------------------------------------------
@jit
def body_to_ned(sin: Trig, cos: Trig, u: ArrayLike, v: ArrayLike, w: ArrayLike):
    """``Rzyx [u v w]``: a body-axes vector (e.g. the velocity) in NED, one array each."""
    sphi, sth, spsi = sin
    cphi, cth, cpsi = cos
    b = cphi * v - sphi * w
    c = sphi * v + cphi * w
    a = cth * u + sth * c
    return cpsi * a - spsi * b, spsi * a + cpsi * b, cth * c - sth * u


@jit
def ned_to_body(sin: Trig, cos: Trig, north: ArrayLike, east: ArrayLike, down: ArrayLike):
    """``Rzyx^T [north east down]``: an NED vector (e.g. a current) in body axes."""
    sphi, sth, spsi = sin
    cphi, cth, cpsi = cos
    a = cpsi * north + spsi * east
    b = cpsi * east - spsi * north
    c = sth * a + cth * down
    return cth * a - sth * down, cphi * b + sphi * c, cphi * c - sphi * b


@jit
def euler_rates(sin: Trig, cos: Trig, p: ArrayLike, q: ArrayLike, r: ArrayLike):
    """``Tzyx [p q r]``: the Euler-angle rates ``(phi_dot, theta_dot, psi_dot)`` (only the roll
    and pitch entries of ``sin``/``cos`` are used)."""
    sphi, sth, _ = sin
    cphi, cth, _ = cos
    t1 = q * sphi + r * cphi
    sec = 1.0 / cth
    return p + t1 * sth * sec, q * cphi - r * sphi, t1 * sec


# -- component forms (3 DOF, the horizontal plane) -------------------------------------------------
@jit
def planar_to_ned(cos_psi: ArrayLike, sin_psi: ArrayLike, u: ArrayLike, v: ArrayLike):
    """``R(psi) [u v]``: surge and sway components in north and east."""
    return cos_psi * u - sin_psi * v, sin_psi * u + cos_psi * v


@jit
def planar_to_body(cos_psi: ArrayLike, sin_psi: ArrayLike, north: ArrayLike, east: ArrayLike):
    """``R(psi)^T [north east]``: a horizontal NED vector (a current, a wind) in surge and
    sway."""
    return cos_psi * north + sin_psi * east, cos_psi * east - sin_psi * north
