"""The hovercraft model (docs/models.md section 5) and the manoeuvre tests
(marine_envs.manoeuvres)."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from marine_envs.manoeuvres import ZigzagRudder, turning_circle, zigzag
from marine_envs.models import get_model
from marine_envs.models.base import VehicleModel
from marine_envs.models.hovercraft import HovercraftModel, HovercraftParams

CRUISE = 32 * 1852 / 3600  # 32 kn, m/s


@pytest.fixture(scope="module")
def model():
    return HovercraftModel()


@pytest.fixture(scope="module")
def full_pitch_turns(model):
    """Rudder 0, 5, 15, 30 deg at full pitch (sigma = 1) from the 32 kn trim, one batch: the
    0-deg run gives the top speed, the others the turning table of docs/models.md 5.3."""
    return turning_circle(model, np.radians([0.0, 5.0, 15.0, 30.0]), inputs=[1.0, 1.0, 0.0],
                          duration=150.0, dt=0.1)  # steady values: dt-independent


@pytest.fixture(scope="module")
def zigzags(model):
    """5/5, 15/15, 25/25 at 32 kn and 15/15 at 12 and 20 m/s, one batch."""
    angles = np.radians([5.0, 15.0, 25.0, 15.0, 15.0])
    return zigzag(model, angles, angles, speed=[CRUISE, CRUISE, CRUISE, 12.0, 20.0], dt=0.05)


def test_registry_names_and_bounds(model):
    m = get_model("hovercraft")
    assert isinstance(m, HovercraftModel) and m.name == "hovercraft"
    assert m.state_names == ("u", "v", "r", "north", "east", "psi")
    assert m.input_names == ("sigma_1", "sigma_2", "delta")
    assert m.disturbance_names == ("wind_north", "wind_east")
    assert len(m.state_units) == 6 and len(m.input_units) == 3 and len(m.disturbance_units) == 2
    low, high = m.u_bounds
    np.testing.assert_allclose(low, [-0.5, -0.5, -math.radians(30)])
    np.testing.assert_allclose(high, [1.0, 1.0, math.radians(30)])
    assert m.params.resolved().Iz == pytest.approx(1.1268e7, rel=1e-4)  # docs/models.md 5.3


def test_equilibrium_at_the_nominal_point(model):
    x0, u0 = model.x0, model.u0
    assert x0[0] == pytest.approx(16.462, abs=1e-3) and not x0[1:].any()
    assert u0[0] == u0[1] and 0 < u0[0] < 1 and u0[2] == 0
    x_dot = model.rhs(x0, u0)
    np.testing.assert_allclose(x_dot[:3], 0.0, atol=1e-12)  # accelerations
    assert x_dot[5] == 0.0 and x_dot[3] == pytest.approx(x0[0])  # psi_dot, north_dot
    for speed in (5.0, 12.0, 20.0):
        x, u = model.trim_point(speed)
        assert model.trim_pitch(speed) == u[0]
        np.testing.assert_allclose(model.rhs(x, u)[:3], 0.0, atol=1e-12)
    assert model.trim_pitch(0.0) == 0.0
    with pytest.raises(ValueError, match="speed"):
        model.trim_pitch(30.0)  # needs more than full pitch


def test_linearize_agrees_with_independent_finite_differences(model):
    x = np.array([14.0, -1.2, 0.03, 120.0, -40.0, 0.7])
    u = np.array([0.8, 0.6, 0.2])
    A, B, E = model.linearize(x, u)
    d0 = np.zeros(2)
    for matrix, point, make in ((A, x, lambda z: (z, u, d0)), (B, u, lambda z: (x, z, d0)),
                                (E, d0, lambda z: (x, u, z))):
        for j in range(point.size):  # one-sided differences, another step: independent of base
            h = 1e-7 * max(1.0, abs(point[j]))
            up = point.copy()
            up[j] += h
            column = (model.rhs(*make(up)) - model.rhs(*make(point))) / h
            np.testing.assert_allclose(matrix[:, j], column, rtol=1e-4, atol=1e-8)
    # kinematic rows are known in closed form
    c, s = math.cos(x[5]), math.sin(x[5])
    np.testing.assert_allclose(A[3], [c, -s, 0, 0, 0, -x[0] * s - x[1] * c], atol=1e-7)
    np.testing.assert_allclose(A[4], [s, c, 0, 0, 0, x[0] * c - x[1] * s], atol=1e-7)
    np.testing.assert_allclose(A[5], [0, 0, 1, 0, 0, 0], atol=1e-9)
    assert B[2, 0] > 0 > B[2, 1] and B[2, 2] > 0  # port thrust and +delta turn to starboard


def test_rhs_batched_matches_loop(model):
    rng = np.random.default_rng(4)
    n = 1024
    x = np.column_stack([rng.uniform(-5, 25, n), rng.uniform(-4, 4, n), rng.uniform(-0.1, 0.1, n),
                         rng.normal(0, 500, n), rng.normal(0, 500, n), rng.uniform(-4, 4, n)])
    u = np.column_stack([rng.uniform(-0.5, 1, n), rng.uniform(-0.5, 1, n),
                         rng.uniform(-0.52, 0.52, n)])
    d = rng.normal(0, 8, (n, 2))
    batched = model.rhs(x, u, d)
    looped = np.array([model.rhs(x[i], u[i], d[i]) for i in range(n)])
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(model.rhs(x.reshape(2, 512, 6), u.reshape(2, 512, 3), d[0]),
                               model.rhs(x, u, d[0]).reshape(2, 512, 6), rtol=1e-12, atol=1e-12)
    # zero wind takes the same equations (another summation order: rounding only)
    np.testing.assert_allclose(model.rhs(x, u, np.zeros(2)), model.rhs(x, u), rtol=1e-12,
                               atol=1e-12)


def test_top_speed_at_full_pitch(model, full_pitch_turns):
    res = full_pitch_turns
    assert res.steady[0]
    # docs/models.md 5.3: 20.49 m/s (39.8 kn)
    assert res.surge[0] == pytest.approx(20.49, rel=0.01)
    assert model.trim_pitch(20.49) == pytest.approx(1.0, abs=0.01)
    assert abs(res.states[-1, 0, 1]) < 1e-9 and abs(res.yaw_rate[0]) < 1e-9


def test_turning_table_at_full_pitch(full_pitch_turns):
    """docs/models.md 5.3 turning table; it holds at sigma = 1 (at the 32 kn trim pitch the turns
    are slower: r = 0.82/2.12/3.41 deg/s)."""
    res = full_pitch_turns
    assert res.steady[1:].all()
    np.testing.assert_allclose(res.yaw_rate_deg[1:], [1.17, 2.76, 4.26], rtol=0.02)
    np.testing.assert_allclose(res.drift_angle_deg[1:], [3.5, 8.5, 15.0], atol=0.3)
    np.testing.assert_allclose(res.radius[1:], [990.0, 380.0, 200.0], rtol=0.03)
    assert res.surge[3] == pytest.approx(14.4, rel=0.01)


def test_positive_rudder_turns_to_starboard(model, full_pitch_turns):
    assert model.rhs(model.x0, model.u0 + [0, 0, 0.1])[2] > 0
    res = full_pitch_turns
    assert (res.yaw_rate[1:] > 0).all() and (res.drift_angle[1:] > 0).all()
    # heading 0 = north: a starboard turn moves the craft east
    assert (res.track[-1, 1:, 1] > 0).all() and (res.transfer[1:] > 0).all()
    assert res.tactical_diameter[3] < res.tactical_diameter[2]  # 5 deg: 180 deg not reached
    assert math.isnan(res.tactical_diameter[1]) and res.advance[1] > res.advance[2]


def test_zigzags_at_32_knots(zigzags):
    """docs/models.md 5.3: maximum heading 6.0, 17.2, 27.7 deg (overshoot 1-2.7 deg)."""
    res = zigzags
    np.testing.assert_allclose(res.max_heading_deg[:3], [6.0, 17.2, 27.7], atol=0.15)
    assert (res.first_overshoot_deg[:3] > 0.8).all() and (res.first_overshoot_deg[:3] < 2.8).all()
    assert (res.second_overshoot_deg[:3] > 0.8).all()
    assert (res.second_overshoot_deg[:3] < 2.8).all()
    assert (np.diff(res.first_overshoot[:3]) > 0).all()
    # the rudder starts to starboard and reverses when the heading change reaches +-B
    np.testing.assert_allclose(res.rudder[0, :3], np.radians([5, 15, 25]))
    for j in range(5):
        steps = np.round(res.reversal_times[j] / 0.05).astype(int)
        b = res.switch[j]
        assert res.heading_change[steps[0], j] >= b > res.heading_change[steps[0] - 1, j]
        assert res.heading_change[steps[1], j] <= -b < res.heading_change[steps[1] - 1, j]
    assert (res.initial_turning_time < res.first_peak_time).all()
    assert (res.period > 2 * res.time_to_check_yaw).all()


def test_overshoot_grows_with_speed(zigzags):
    low, cruise, high = zigzags.first_overshoot[[3, 1, 4]]
    assert low < cruise < high


def test_head_wind_reduces_cruise_speed(model):
    u0 = model.u0

    def steady_speed(wind, psi=0.0):
        def u_dot(speed):
            return model.rhs([speed, 0, 0, 0, 0, psi], u0, wind)[0]
        return brentq(u_dot, 0.0, 40.0)

    assert steady_speed([0.0, 0.0]) == pytest.approx(CRUISE, rel=1e-9)
    head, tail = steady_speed([-10.0, 0.0]), steady_speed([10.0, 0.0])
    assert head < CRUISE - 1.0 and tail > CRUISE + 1.0
    # the wind is a NED vector: heading east into an air flow moving west is the same head wind
    assert steady_speed([0.0, -10.0], psi=math.pi / 2) == pytest.approx(head, rel=1e-9)
    # air moving to starboard pushes the craft to starboard
    assert model.rhs(model.x0, u0, [0.0, 10.0])[1] > 0


def test_zigzag_rudder_on_a_batch():
    law = ZigzagRudder([0.1, 0.2, 0.3], 0.2, batch_size=3)
    law.reset(initial_heading=[0.0, 3.1, -1.0])
    np.testing.assert_allclose(law([0.0, 3.1, -1.0]), [0.1, 0.2, 0.3])
    # boat 0 reaches +B, boat 1 crosses +B through the +-pi wrap, boat 2 not yet
    np.testing.assert_allclose(law([0.2, 3.1 + 0.25 - 2 * np.pi, -0.9]), [-0.1, -0.2, 0.3])
    np.testing.assert_allclose(law([0.1, 3.3, -0.7]), [-0.1, -0.2, -0.3])
    np.testing.assert_allclose(law([-0.2, 2.95, -1.1]), [0.1, -0.2, -0.3])
    np.testing.assert_array_equal(law.reversals, [2, 1, 1])
    law.reset([1], initial_heading=0.5)  # only boat 1
    np.testing.assert_allclose(law([-0.1, 0.5, -1.0]), [0.1, 0.2, -0.3])
    np.testing.assert_array_equal(law.reversals, [2, 0, 1])
    # headings given per selected boat (in idx order) or for the whole batch
    law.reset(np.array([2, 0]), initial_heading=np.array([0.3, -0.4]))
    np.testing.assert_allclose(law.initial_heading, [-0.4, 0.5, 0.3])
    law.reset(np.array([True, False, True]), initial_heading=np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(law.initial_heading, [1.0, 0.5, 3.0])
    law.reset(np.array([2, 1, 0]), initial_heading=np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(law.initial_heading, [3.0, 2.0, 1.0])
    with pytest.raises(ValueError, match="rudder_index"):  # apply() needs the columns
        law.apply(np.zeros((3, 6)), np.ones((3, 3)))


def test_zigzag_rudder_rate_limit_and_apply():
    law = ZigzagRudder(0.2, 0.1, batch_size=2, rudder_rate=0.05, rudder_index=2,
                       heading_index=5)
    law.reset(initial_heading=0.0)
    x = np.zeros((2, 6))
    u = law.apply(x, np.ones((2, 3)), dt=1.0)
    np.testing.assert_allclose(u, [[1, 1, 0.05], [1, 1, 0.05]])
    x[1, 5] = 0.1
    np.testing.assert_allclose(law.apply(x, u, dt=1.0)[:, 2], [0.1, 0.0])
    with pytest.raises(ValueError, match="dt"):
        law(x[:, 5])
    with pytest.raises(ValueError, match="amplitude"):
        ZigzagRudder(-0.1, 0.1)


def test_manoeuvres_work_on_another_model():
    usv = get_model("usv")  # Kdr < 0: a positive rudder turns it to port
    res = zigzag(usv, 0.1, 0.02, turn_sign=-1, dt=0.1)
    assert res.rudder[0] == pytest.approx(0.1) and res.initial_turning_time > 0
    assert res.heading_change[round(res.initial_turning_time / 0.1)] <= -0.02
    assert res.first_overshoot > 0 and res.second_overshoot > 0 and res.period > 0
    with pytest.raises(TypeError, match="trim_point"):
        zigzag(usv, 0.1, 0.1, speed=5.0)


def test_bad_params_raise_naming_the_parameter(model):
    for name, value in (("m", -1.0), ("T0", math.nan), ("x_R", 5.0), ("Iz", -1.0),
                        ("sigma_max", 0.0), ("sigma_min", 0.2), ("delta_max", 2.0),
                        ("u_cruise", 60.0), ("N_vd", 1e7), ("C_R4", math.inf), ("L", 0.0)):
        with pytest.raises(ValueError, match=rf"^{name}="):
            HovercraftParams(**{name: value})
    with pytest.raises(ValueError, match="x_R"):
        get_model("hovercraft", x_R=1.0)
    with pytest.raises(ValueError, match="unknown parameter"):
        model.with_params(X_Hud=1.0)
    heavy = model.with_params(m=1.8e5)  # derived inertia and added mass follow the mass
    assert heavy.params.Iz is None
    assert heavy.params.resolved().Iz == pytest.approx(1.2 * model.params.resolved().Iz)
    assert dataclasses.replace(model.params, Iz=2e7).resolved().N_rd == pytest.approx(-1e6)
    assert isinstance(heavy, VehicleModel)
