"""Rigid-body kinematics written once (marine_envs.models.kinematics): Fossen's Rzyx, Tzyx and
Smtrx, and the component forms the models' right-hand sides use."""

import numpy as np
import pytest

from marine_envs.models.kinematics import (
    Rzyx,
    Tzyx,
    body_to_ned,
    euler_rates,
    ned_to_body,
    planar_to_body,
    planar_to_ned,
    skew,
)

ANGLES = [(0.0, 0.0, 0.0), (0.3, -0.2, 1.1), (-1.0, 0.9, -2.8), (0.05, 1.4, 3.1)]


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize("phi, theta, psi", ANGLES)
def test_rzyx_is_the_zyx_rotation_and_orthonormal(phi, theta, psi):
    R = Rzyx(phi, theta, psi)
    np.testing.assert_allclose(R, _rz(psi) @ _ry(theta) @ _rx(phi), atol=1e-15)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)


@pytest.mark.parametrize("phi, theta, psi", ANGLES)
def test_euler_rates_turn_the_rotation_as_the_body_rates_do(phi, theta, psi):
    # R_dot = R S(omega): the Euler-angle rates of Tzyx omega move Rzyx exactly so
    omega, h = np.array([0.3, -0.5, 0.7]), 1e-6
    rates = Tzyx(phi, theta) @ omega
    plus = Rzyx(*(np.array([phi, theta, psi]) + h * rates))
    minus = Rzyx(*(np.array([phi, theta, psi]) - h * rates))
    np.testing.assert_allclose((plus - minus) / (2 * h), Rzyx(phi, theta, psi) @ skew(omega),
                               atol=1e-8)


def test_component_forms_are_the_matrices_on_batches():
    rng = np.random.default_rng(0)
    angles = rng.uniform(-1.2, 1.2, (3, 7))
    vectors = rng.standard_normal((3, 7))
    sin, cos = np.sin(angles), np.cos(angles)
    ned = np.array(body_to_ned(sin, cos, *vectors))
    rates = np.array(euler_rates(sin, cos, *vectors))
    for i in range(7):
        R = Rzyx(*angles[:, i])
        np.testing.assert_allclose(ned[:, i], R @ vectors[:, i], atol=1e-14)
        np.testing.assert_allclose(rates[:, i], Tzyx(*angles[:2, i]) @ vectors[:, i],
                                   atol=1e-13)
    np.testing.assert_allclose(np.array(ned_to_body(sin, cos, *ned)), vectors, atol=1e-14)


def test_planar_forms_are_the_yaw_rotation():
    psi, u, v = 0.7, np.array([1.0, -2.0]), np.array([0.5, 3.0])
    c, s = np.cos(psi), np.sin(psi)
    north, east = planar_to_ned(c, s, u, v)
    np.testing.assert_allclose(np.array([north, east]), _rz(psi)[:2, :2] @ np.array([u, v]))
    np.testing.assert_allclose(planar_to_body(c, s, north, east), [u, v], atol=1e-15)


def test_skew_is_the_cross_product():
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.4, -1.0])
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b))
    np.testing.assert_allclose(skew(a), -skew(a).T)
