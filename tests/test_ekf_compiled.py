"""The compiled path of the extended Kalman filter (estimators.ekf.kernels): the estimates of the
numpy path it replaced (saved from commit 97dcd08 on the EKF benchmark's record, and the numpy
path run beside it), its pieces against their definitions, and what it does with missing data,
diverging filters and models it cannot compile."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from estimators.ekf import ExtendedKalmanFilter, kernels
from estimators.ekf import dynamics as ekf_dynamics
from estimators.identification import Segment, identify_ekf
from marine_envs.models import get_model
from marine_envs.models.rov import SEED_COEFFICIENTS, ROVModel

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import ekf_throughput as bench  # noqa: E402

#: the benchmark's filter run by the numpy EKF of commit 97dcd08 on a record through the morph
#: (tests/data/make_ekf_rov_reference.py)
REFERENCE = np.load(Path(__file__).parent / "data" / "ekf_rov_reference.npz")


def replay(ekf, steps=None):
    """Filter the saved record; the estimates and standard deviations every ``every`` steps."""
    forces, s_cmd, y, every = (REFERENCE[k] for k in ("forces", "s_cmd", "y", "every"))
    steps = len(forces) if steps is None else steps
    x, std = [], []
    for k in range(steps):
        ekf.disturbance[:, 3] = s_cmd[k]
        ekf.update(y[k])
        ekf.predict(forces[k])
        if k % every == every - 1:
            x.append(ekf.x.copy())
            std.append(ekf.std.copy())
    return np.array(x), np.array(std)


@pytest.fixture(scope="module")
def compiled_run():
    ekf = bench.make_filter(REFERENCE["y"].shape[1], "compiled")
    return ekf, *replay(ekf)


def test_compiled_filter_gives_the_saved_numpy_estimates(compiled_run):
    ekf, x, std = compiled_run
    assert ekf.compiled
    # the estimates to 1e-6 of their standard deviation (measured: 2e-9), the covariances to
    # 1e-8 of their largest entry (measured: 3e-12)
    assert np.abs(x - REFERENCE["x"]).max(initial=0) > 0  # another path, not a copy
    assert (np.abs(x - REFERENCE["x"]) / REFERENCE["std"]).max() < 1e-6
    np.testing.assert_allclose(std, REFERENCE["std"], rtol=1e-6)
    scale = np.abs(REFERENCE["P"]).max(axis=(1, 2), keepdims=True)
    assert (np.abs(ekf.P - REFERENCE["P"]) / scale).max() < 1e-8
    np.testing.assert_array_equal(ekf.diverged, REFERENCE["diverged"])


def test_numpy_path_still_gives_the_saved_estimates():
    """The reference path is kept, and unchanged."""
    ekf = bench.make_filter(REFERENCE["y"].shape[1], "numpy")
    assert not ekf.compiled
    x, _ = replay(ekf, steps=60)
    n = len(x)
    assert (np.abs(x - REFERENCE["x"][:n]) / REFERENCE["std"][:n]).max() < 1e-9


def test_covariances_stay_symmetric_positive_definite(compiled_run):
    ekf, _, _ = compiled_run
    np.testing.assert_array_equal(ekf.P, ekf.P.transpose(0, 2, 1))
    assert np.linalg.eigvalsh(ekf.P).min() > 0


def test_batch_rows_are_their_filters_alone_exactly():
    y = REFERENCE["y"]
    forces, s_cmd = REFERENCE["forces"], REFERENCE["s_cmd"]
    together = bench.make_filter(3)
    bench.run(together, forces, y[:30], s_cmd)
    alone = bench.make_filter(1)
    bench.run(alone, forces, y[:30, 1:2], s_cmd)
    np.testing.assert_array_equal(together.x[1], alone.x[0])
    np.testing.assert_array_equal(together.P[1], alone.P[0])


def random_states(model, n, seed):
    rng = np.random.default_rng(seed)
    x = model.x0 + rng.normal(0, [0.5, 0.2, 0.2, 0.2, 0.2, 0.2, 5, 5, 2, 0.5, 0.4, 3, 0.0], (n, 13))
    x[:, 12] = rng.uniform(0, 1, n)
    u = model.u0 + rng.normal(0, 10, (n, 6))
    d = np.column_stack([rng.normal(0, 0.3, (n, 3)), rng.uniform(0, 1, n)])
    d[::2, :3] = 0.0  # still water too
    theta = np.array([getattr(model.params, k) for k in SEED_COEFFICIENTS])
    return x, u, d, theta * rng.uniform(0.3, 2.0, (n, theta.size))


def test_coefficient_dynamics_are_rhs_with_and_their_jacobian_is_exact():
    model = ROVModel()
    dynamics = ekf_dynamics.compiled_dynamics(model, SEED_COEFFICIENTS)
    x, u, d, theta = random_states(model, 12, 0)
    q = dynamics.constants.copy()
    values = dict(zip(SEED_COEFFICIENTS, theta.T, strict=True))
    expected = model.rhs_with(x, u, d, values)
    jacobian = model.parameter_jacobian(x, u, d, values)
    for i in range(len(x)):
        dynamics.prepare(theta[i], dynamics.table, q)
        out, A = np.empty(13), np.zeros((13, 31))
        dynamics.f(x[i], u[i], d[i], q, out)
        np.testing.assert_allclose(out, expected[i], rtol=1e-12, atol=1e-12)
        dynamics.parameter_jacobian(x[i], u[i], d[i], q, dynamics.table, A)
        np.testing.assert_allclose(A[:, 13:], jacobian[i], rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("scale", [0.05, 1.0, 6.0])
def test_transition_rows_are_the_exponential_of_the_augmented_jacobian(scale):
    """Against scipy's expm, for Jacobians that need no squaring and ones that need several,
    and non-normal ones (large couplings, small eigenvalues: |X| far above alpha)."""
    rng = np.random.default_rng(1)
    A = rng.normal(0, scale / 13, (13, 31))
    A[:, 6:9] = 0.0
    skewed = np.triu(rng.normal(0, 50 * scale, (13, 13)), 1) + np.diag(rng.normal(0, 1, 13))
    for jac in (A, np.hstack([skewed, A[:, 13:]])):
        T = np.empty((13, 31))
        kernels.transition_rows(jac, 0.1, T, np.empty((10, 13, 13)), np.empty((2, 13, 31)))
        augmented = np.zeros((31, 31))
        augmented[:13] = jac * 0.1
        exact = scipy.linalg.expm(augmented)[:13]
        assert np.abs(T - exact).max() <= 1e-12 * np.abs(exact).max()


def test_missing_channels_get_no_gain_and_match_the_numpy_path():
    y = REFERENCE["y"][:12].copy()
    y[5, 0] = np.nan  # every channel of filter 0 missing
    y[5, 1, :4] = np.nan
    runs = {}
    for path in ("compiled", "numpy"):
        ekf = bench.make_filter(3, path)
        bench.run(ekf, REFERENCE["forces"], y[:5], REFERENCE["s_cmd"])
        before = ekf.x[0].copy(), ekf.P[0].copy()
        ekf.update(y[5], mask=np.array([[True] * 10, [True] * 10, [True] * 9 + [False]]))
        np.testing.assert_array_equal(ekf.x[0], before[0])
        np.testing.assert_array_equal(ekf.P[0], before[1])
        assert ekf.dof.tolist() == [0, 6, 9]
        runs[path] = ekf
    a, b = runs["compiled"], runs["numpy"]
    assert (np.abs(a.x - b.x) / b.std).max() < 1e-8
    np.testing.assert_allclose(a.innovation_cov, b.innovation_cov, rtol=0,
                               atol=1e-9 * np.abs(b.innovation_cov).max())
    np.testing.assert_allclose(a.nis, b.nis, rtol=1e-8)


def test_a_state_measured_far_more_precisely_than_known_keeps_its_small_variance():
    """The morph fraction known to 1e-6 and measured to 1e-18: its variance after the update is
    1e-36, which P - K S K' would lose to cancellation (the Joseph form is used there)."""
    model = ROVModel()
    P0 = np.diag(np.r_[np.full(12, 1e-2), 1e-12])
    R = np.r_[np.full(3, 1e-4), 1e-36]
    runs = []
    for compiled in (True, False):
        ekf = ExtendedKalmanFilter.from_model(model, 0.1, measured=["u", "v", "w", "s"],
                                              Q=np.full(13, 1e-8), R=R, P0=P0,
                                              compiled=compiled)
        ekf.update([[1.5, 0.0, 0.0, 0.0]])
        runs.append(ekf.P[0])
    compiled_P, numpy_P = runs
    np.testing.assert_allclose(compiled_P[12, 12], 1e-36, rtol=1e-9)
    np.testing.assert_allclose(compiled_P, numpy_P, rtol=1e-9, atol=1e-16)
    assert np.linalg.eigvalsh(compiled_P).min() > 0


def test_a_filter_gone_bad_is_flagged_and_left_alone():
    ekf = bench.make_filter(3)
    forces, y = REFERENCE["forces"], REFERENCE["y"]
    bench.run(ekf, forces, y[:5], REFERENCE["s_cmd"])
    ekf.x[0, 0] = np.nan  # a non-finite estimate
    ekf.P[2] *= -1.0  # a covariance that is not positive definite
    good = bench.make_filter(1)
    bench.run(good, forces, y[:5, 1:2], REFERENCE["s_cmd"])
    P_bad = ekf.P[2].copy()
    ekf.update(y[5])
    assert ekf.diverged.tolist() == [True, False, True]
    np.testing.assert_array_equal(ekf.P[2], P_bad)  # no update made
    good.update(y[5, 1:2])
    np.testing.assert_array_equal(ekf.x[1], good.x[0])


def test_the_smoother_runs_on_the_compiled_transition():
    forces, s_cmd, y = REFERENCE["forces"][:40], REFERENCE["s_cmd"][:40], REFERENCE["y"][:40, :1]
    runs = []
    for path in ("compiled", "numpy"):
        ekf = bench.make_filter(1, path)
        ekf.disturbance[:, 3] = s_cmd[-1]  # the morph command held (filter() takes no d)
        runs.append(ekf.smooth(forces, y))
    compiled, numpy_path = runs
    np.testing.assert_allclose(compiled.filtered.transition, numpy_path.filtered.transition,
                               rtol=1e-6, atol=1e-9)
    assert (np.abs(compiled.x - numpy_path.x) / numpy_path.std).max() < 1e-6


@pytest.mark.parametrize("name", ["usv", "hovercraft", "nomoto"])
def test_a_model_without_parameters_filters_as_the_numpy_path(name):
    model = get_model(name)
    n = len(model.state_names)
    channels = list(model.state_names)
    rng = np.random.default_rng(3)
    steps = 30
    u = model.u0 + 0.1 * max(np.abs(model.u0).max(), 0.1) * rng.normal(
        size=(steps, len(model.u0)))
    x, ys = model.x0.copy(), []
    for k in range(steps):
        ys.append(x[[model.state_names.index(c) for c in channels]])
        for _ in range(4):
            x = x + 0.025 * model.rhs(x, u[k])
    y = np.array(ys) + 1e-3 * rng.normal(size=(steps, len(channels)))
    runs = {}
    for compiled in (True, False):
        ekf = ExtendedKalmanFilter.from_model(model, 0.1, measured=channels,
                                              Q=np.full(n, 1e-6), R=np.full(n, 1e-6),
                                              compiled=compiled, batch_size=2)
        assert ekf.compiled == compiled
        runs[compiled] = ekf.filter(u, y)
    a, b = runs[True], runs[False]
    assert (np.abs(a.x - b.x) / b.std).max() < 1e-6
    np.testing.assert_allclose(a.P, b.P, rtol=1e-6, atol=1e-12 * np.abs(b.P).max())


def test_what_cannot_be_compiled_runs_the_numpy_path():
    rov, hovercraft, dp = ROVModel(), get_model("hovercraft"), get_model("dp_vessel")
    kwargs = {"dt": 0.1, "measured": ["u", "r"], "R": [1e-4, 1e-4]}
    assert not ExtendedKalmanFilter.from_model(rov, Q=np.ones(13), parameters=["m"],
                                               **kwargs).compiled
    assert not ExtendedKalmanFilter.from_model(hovercraft, Q=np.ones(6), parameters=["N_Hr"],
                                               **kwargs).compiled
    assert not ExtendedKalmanFilter.from_model(rov, Q=np.ones(13), compiled=False,
                                               **kwargs).compiled
    assert not ExtendedKalmanFilter.from_model(  # outputs that are not states
        dp, dt=0.1, measured=["north", "east"], Q=np.ones(15), R=[1.0, 1.0]).compiled
    assert ExtendedKalmanFilter.from_model(rov, Q=np.ones(13), parameters=["Xuu"],
                                           **kwargs).compiled


def test_identification_of_the_rov_runs_compiled_and_as_the_numpy_path():
    """identify_ekf over two segments of the record (the shorter one padded with missing
    samples), fused: the compiled and the numpy path agree."""
    forces, s_cmd, y = REFERENCE["forces"], REFERENCE["s_cmd"], REFERENCE["y"]
    d = np.column_stack([np.zeros((len(s_cmd), 3)), s_cmd])
    segments = [Segment(time=np.arange(T) * bench.DT, inputs=forces[:T], measurements=y[:T, i],
                        measured=bench.MEASURED, disturbance=d[:T], angular=("psi",),
                        name=f"run {i}") for i, T in enumerate((120, 90))]
    names = ("Xuu", "Nrr", "Yvv", "Zww")
    results = [identify_ekf(ROVModel(), segments, names, measurement_std=bench.NOISE,
                            compiled=compiled) for compiled in (True, False)]
    compiled, numpy_path = results
    assert compiled.info["compiled"] and not numpy_path.info["compiled"]
    assert (np.abs(compiled.estimate - numpy_path.estimate) / numpy_path.std).max() < 1e-6
    np.testing.assert_allclose(compiled.std, numpy_path.std, rtol=1e-6)
