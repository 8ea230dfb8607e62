"""The morphing-robot patent: the ROV model's coefficient interface, and online identification
through a morph."""

import numpy as np
import pytest

from agents.reproduce import rov_online_id as rid
from marine_envs.models.rov import (
    HYDRO_COEFFICIENTS,
    MORPHING,
    SEED_COEFFICIENTS,
    ROVModel,
)

S = 12  # index of the morph fraction in the state


def random_batch(n, seed, s=None):
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.normal(0, [1.0, 0.3, 0.3, 0.3, 0.3, 0.3], (n, 6)),
                        rng.normal(0, 5, (n, 3)), rng.uniform(-1, 1, (n, 3)),
                        rng.uniform(0, 1, (n, 1))], axis=1)
    if s is not None:
        x[:, S] = s
    u = rng.normal(0, 10, (n, 6))
    d = np.concatenate([rng.normal(0, 0.3, (n, 3)), rng.uniform(0, 1, (n, 1))], axis=1)
    d[::3, :3] = 0.0  # some in still water
    return x, u, d


def shifted(model, name, delta):
    """The model with coefficient ``name`` shifted by ``delta`` in both shapes."""
    changes = {name: getattr(model.params, name) + delta}
    if name in MORPHING:
        changes[f"work_{name}"] = getattr(model.params, f"work_{name}") + delta
    return model.with_params(**changes)


def seed_values(model, n, rng):
    """Per-row coefficient values (dissipative ones kept <= 0 so with_params accepts them)."""
    return {k: getattr(model.params, k) - np.abs(rng.normal(0, 2.0, n)) for k in SEED_COEFFICIENTS}


def test_seed_coefficients_are_the_eighteen_of_the_seed():
    assert len(SEED_COEFFICIENTS) == len(set(SEED_COEFFICIENTS)) == 18
    assert set(SEED_COEFFICIENTS) <= set(HYDRO_COEFFICIENTS)
    assert {"Xuu", "Nrr", "Kpp", "Yuv", "Nur"} <= set(SEED_COEFFICIENTS)


def test_regressors_are_the_exact_derivative_of_the_forces():
    model = ROVModel()
    x, u, d = random_batch(40, 0)
    phi = model.hydrodynamic_regressors(x, HYDRO_COEFFICIENTS, d)
    assert phi.shape == (40, 6, len(HYDRO_COEFFICIENTS))
    base = model.forces(x, u, d)
    for j, name in enumerate(HYDRO_COEFFICIENTS):
        change = shifted(model, name, -1.0).forces(x, u, d) - base
        np.testing.assert_allclose(change, -phi[..., j], atol=1e-10, err_msg=name)
        assert np.count_nonzero(np.abs(phi[..., j]).max(axis=0)) == 1  # one force row


def test_rhs_with_in_cruise_shape_equals_a_model_with_those_values():
    model = ROVModel()
    x, u, d = random_batch(6, 1, s=0.0)
    values = seed_values(model, 6, np.random.default_rng(1))
    out = model.rhs_with(x, u, d, values)
    for i in range(6):
        other = model.with_params(**{k: float(v[i]) for k, v in values.items()})
        np.testing.assert_allclose(out[i], other.rhs(x[i], u[i], d[i]), atol=1e-10)


def test_rhs_with_replaces_the_coefficient_at_the_current_shape():
    """At s = 0.5 the given value replaces c(0.5): nu_dot changes by M(s)^-1 Phi (theta - c(s))."""
    model = ROVModel()
    x, u, d = random_batch(8, 2, s=0.5)
    values = seed_values(model, 8, np.random.default_rng(2))
    shape = model.coefficients(0.5)
    delta = np.column_stack([values[k] - shape[k] for k in SEED_COEFFICIENTS])
    force = np.einsum("nij,nj->ni", model.hydrodynamic_regressors(x, SEED_COEFFICIENTS, d), delta)
    expected = model.rhs(x, u, d)
    expected[:, :6] += np.linalg.solve(model.mass_matrix(0.5), force.T).T
    np.testing.assert_allclose(model.rhs_with(x, u, d, values), expected, atol=1e-10)
    # the interpolated values themselves change nothing
    same = {k: shape[k] for k in SEED_COEFFICIENTS}
    np.testing.assert_allclose(model.rhs_with(x, u, d, same), model.rhs(x, u, d), atol=1e-12)


def test_rhs_with_broadcasts_scalars_and_per_row_values():
    model = ROVModel()
    x, u, d = random_batch(5, 3)
    rows = model.rhs_with(x, u, d, {"Xuu": np.full(5, -4.0), "Nrr": -90.0})
    one = model.rhs_with(x[2], u[2], d[2], {"Xuu": -4.0, "Nrr": -90.0})
    np.testing.assert_allclose(rows[2], one, atol=1e-12)
    fleet = model.rhs_with(x[0], u[0], d[0], {"Xuu": np.array([-2.0, -8.0])})
    assert fleet.shape == (2, 13) and fleet[0, 0] > fleet[1, 0]  # more drag, less accel.


def test_rhs_with_mixes_coefficients_with_other_parameters():
    model = ROVModel()
    x, u, d = random_batch(3, 4, s=0.3)
    out = model.rhs_with(x, u, d, {"Xuu": -5.0, "m": 32.0})
    direct = model.with_params(Xuu=-5.0, work_Xuu=-5.0, m=32.0).rhs(x, u, d)
    np.testing.assert_allclose(out, direct, atol=1e-10)
    with pytest.raises(ValueError, match="work_Xuu"):
        model.rhs_with(x, u, d, {"Xuu": -5.0, "work_Xuu": -9.0})


def test_parameter_jacobian_is_exact():
    model = ROVModel()
    x, u, d = random_batch(10, 5)
    values = seed_values(model, 10, np.random.default_rng(5))
    jac = model.parameter_jacobian(x, u, d, values)
    assert jac.shape == (10, 13, 18) and not jac[:, 6:].any()
    base = model.rhs_with(x, u, d, values)
    for j, name in enumerate(SEED_COEFFICIENTS):
        bumped = dict(values, **{name: values[name] + 1.0})
        np.testing.assert_allclose(model.rhs_with(x, u, d, bumped) - base, jac[..., j],
                                   atol=1e-10, err_msg=name)


def test_unknown_coefficient_raises_naming_it():
    with pytest.raises(ValueError, match="Xvv"):
        ROVModel().hydrodynamic_regressors(np.zeros(13), ["Xuu", "Xvv"])


# -- online identification through the morph (one flight shared by the tests below) ------------
@pytest.fixture(scope="module")
def flight():
    run = rid.fly(seeds=2, morph_time=40.0, duration=110.0, seed=7)
    return run, rid.summarise(run)


def test_surge_and_yaw_drag_are_tracked_within_a_minute_of_the_morph(flight):
    run, summary = flight
    for name in rid.TRACKED:
        times = rid.tracking_time(run, name)
        assert all(t < 60.0 for t in times), (name, times)  # NaN fails too
    xuu = summary["coefficients"]["Xuu"]
    assert abs(xuu["estimate_before"] / xuu["true_before"] - 1) < 0.1
    assert abs(xuu["estimate_after"] / xuu["true_after"] - 1) < 0.05
    assert summary["tracking_time_s"] < 60.0 and summary["diverged"] == 0


def test_identified_feedforward_tracks_better_after_the_morph(flight):
    _, summary = flight
    ff, nominal = summary["feedforward"], summary["nominal"]
    assert ff["rms_tracking_error"] < 0.85 * nominal["rms_tracking_error"]
    assert max(ff["rms_tracking_error_spread"]["per_seed"]) < \
        min(nominal["rms_tracking_error_spread"]["per_seed"])
    assert ff["rms_by_channel_after"]["u"] < nominal["rms_by_channel_after"]["u"]


def test_a_coefficient_the_manoeuvre_does_not_excite_stays_uncertain(flight):
    """q|q| in heave: pitch rates of 0.03 rad/s rms make Zqq's force ~0.003 N, invisible."""
    _, summary = flight
    zqq, xuu = summary["coefficients"]["Zqq"], summary["coefficients"]["Xuu"]
    assert zqq["std_after"] > 0.9 * zqq["prior_std"]
    assert zqq["identifiability"] == "unidentified" and "Zqq" in summary["unidentified"]
    assert xuu["std_after"] < 0.05 * abs(xuu["true_after"])
    assert xuu["identifiability"] == "identified"
