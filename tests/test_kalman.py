"""Kalman and adaptive Kalman filters: optimality, consistency, batching, bad input."""

import pickle
from pathlib import Path

import numpy as np
import pytest
import scipy.stats

from estimators import AdaptiveKalmanFilter, KalmanFilter
from estimators.kalman import held_noise_covariance
from marine_envs.models import get_model, zoh

N_X, N_Y = 4, 2


def system(seed: int = 0):
    """A stable, observable 4-state / 2-measurement discrete system with known noise."""
    rng = np.random.default_rng(seed)
    A = np.array([[0, 1, 0, 0], [-1.0, -0.4, 0.3, 0], [0, 0, 0, 1], [0.2, 0, -2.0, -0.6]])
    F, G = zoh(A, rng.normal(size=(4, 1)), 0.1)
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    Q = held_noise_covariance(A, np.eye(4), 0.1, np.diag([0.1, 0.2, 0.1, 0.3]))
    R = np.diag([0.05, 0.02])
    return F, G, H, Q, R


def simulate(F, G, H, Q, R, steps, batch, seed=0, x0_cov=None):
    """True states, inputs and measurements of ``batch`` independent runs of the system."""
    rng = np.random.default_rng(seed)
    n = F.shape[0]
    x = rng.multivariate_normal(np.zeros(n), np.eye(n) if x0_cov is None else x0_cov, batch)
    xs, us, ys = [], [], []
    for _ in range(steps):
        u = np.sin(0.3 * len(xs)) * np.ones((batch, 1))
        x = x @ F.T + u @ G.T + rng.multivariate_normal(np.zeros(n), Q, batch)
        y = x @ H.T + rng.multivariate_normal(np.zeros(H.shape[0]), R, batch)
        xs.append(x), us.append(u), ys.append(y)
    return np.array(xs), np.array(us), np.array(ys)


def run(kf, us, ys, masks=None):
    est, cov = [], []
    for k in range(len(us)):
        kf.predict(us[k])
        x, P = kf.update(ys[k], None if masks is None else masks[k])
        est.append(x.copy()), cov.append(np.array(P))
    return np.array(est), np.array(cov)


def test_covariance_converges_to_the_riccati_solution():
    F, G, H, Q, R = system()
    kf = KalmanFilter(F, G, H, Q, R, dt=0.1, P0=10 * np.eye(4))
    xs, us, ys = simulate(F, G, H, Q, R, 300, 1)
    run(kf, us, ys)
    _, P_upd = kf.steady_state_covariance()
    np.testing.assert_allclose(kf.P[0], P_upd, rtol=1e-8, atol=1e-12)


def test_nees_and_nis_lie_in_their_95_percent_bands_in_90_percent_of_100_runs():
    """At a given step, the NEES of independent runs is chi2(n) and the NIS chi2(m) when the
    filter is consistent; innovations are also white, so the time-averaged NIS is chi2(m K)/K."""
    F, G, H, Q, R = system()
    steps, runs = 200, 100
    P0 = np.eye(4)
    xs, us, ys = simulate(F, G, H, Q, R, steps, runs, seed=1, x0_cov=P0)
    kf = KalmanFilter(F, G, H, Q, R, dt=0.1, P0=P0, batch_size=runs)
    nis_sum = np.zeros(runs)

    def inside(stat, dof, samples=1):
        lo, hi = scipy.stats.chi2.ppf([0.025, 0.975], dof * samples) / samples
        return ((stat > lo) & (stat < hi)).mean()

    for k in range(steps):
        kf.predict(us[k])
        x, P = kf.update(ys[k])
        nis_sum += kf.nis
        if k + 1 in (10, 50, 200):
            e = xs[k] - x
            nees = np.einsum("ni,ni->n", e, np.linalg.solve(P, e[:, :, None])[:, :, 0])
            assert inside(nees, N_X) >= 0.90
            assert inside(kf.nis, N_Y) >= 0.90
    assert inside(nis_sum / steps, N_Y, steps) >= 0.90


def test_a_wrong_model_fails_the_nis_test():
    """The consistency test can fail: a filter that underestimates Q is caught."""
    F, G, H, Q, R = system()
    xs, us, ys = simulate(F, G, H, Q, R, 200, 100, seed=2)
    kf = KalmanFilter(F, G, H, Q / 20, R, dt=0.1, batch_size=100)
    nis = np.zeros(100)
    for k in range(200):
        kf.predict(us[k])
        kf.update(ys[k])
        nis += kf.nis
    hi = scipy.stats.chi2.ppf(0.975, N_Y * 200) / 200
    assert (nis / 200 > hi).mean() > 0.9


def test_adaptive_trigger_fires_on_ten_percent_of_nominal_steps():
    F, G, H, Q, R = system()
    steps, runs = 500, 40
    xs, us, ys = simulate(F, G, H, Q, R, steps, runs, seed=3)
    akf = AdaptiveKalmanFilter(F, G, H, Q, R, Q_max=10 * Q, dt=0.1, batch_size=runs)
    fired, high = 0.0, 0.0
    for k in range(steps):
        akf.predict(us[k])
        akf.update(ys[k])
        if k >= 50:  # after the start-up transient
            fired += akf.fired.mean()
            high += akf.high.mean()
    rate = fired / (steps - 50)
    assert 0.08 <= rate <= 0.12
    assert 0 < high / (steps - 50) < 0.5  # it does switch, and back


def test_adaptive_filter_tracks_better_when_the_process_noise_jumps():
    """Q grows 30-fold half-way: the AKF moves to Q_max and beats the KF tuned for the calm."""
    F, G, H, Q, R = system()
    rng = np.random.default_rng(4)
    runs, steps = 20, 400
    x = np.zeros((runs, 4))
    xs, ys = [], []
    for k in range(steps):
        q = Q if k < steps // 2 else 30 * Q
        x = x @ F.T + rng.multivariate_normal(np.zeros(4), q, runs)
        xs.append(x)
        ys.append(x @ H.T + rng.multivariate_normal(np.zeros(2), R, runs))
    u = np.zeros((runs, 1))
    result = {}
    for name, f in (("akf", AdaptiveKalmanFilter(F, G, H, Q, R, Q_max=30 * Q, dt=0.1,
                                                 batch_size=runs)),
                    ("kf", KalmanFilter(F, G, H, Q, R, dt=0.1, batch_size=runs))):
        high, sq = [], []
        for k in range(steps):
            f.predict(u)
            f.update(ys[k])
            high.append(getattr(f, "high", np.zeros(1)).mean())
            sq.append(((f.x - xs[k]) ** 2).sum(axis=1).mean())
        half = steps // 2
        result[name] = (np.mean(high[50:half]), np.mean(high[half + 20:]),
                        np.sqrt(np.mean(sq[half + 20:])))
    calm_share, rough_share, akf_error = result["akf"]
    assert calm_share < 0.2 and rough_share > 0.35
    assert akf_error < 0.95 * result["kf"][2]


def test_batched_filters_equal_single_ones_with_masks_resets_and_switching():
    F, G, H, Q, R = system()
    batch, steps = 6, 80
    xs, us, ys = simulate(F, G, H, Q, R, steps, batch, seed=6)
    rng = np.random.default_rng(7)
    masks = rng.random((steps, batch, 2)) > 0.2
    ys[10, 2, 1] = np.nan  # a NaN counts as missing
    for cls, kw in ((KalmanFilter, {}), (AdaptiveKalmanFilter, {"Q_max": 5 * Q})):
        many = cls(F, G, H, Q, R, dt=0.1, batch_size=batch, **kw)
        est = []
        for k in range(steps):
            if k == 40:
                many.reset(np.ones(4), 2 * np.eye(4), idx=[1, 4])
            many.predict(us[k])
            est.append(many.update(ys[k], masks[k])[0].copy())
        for i in range(batch):
            one = cls(F, G, H, Q, R, dt=0.1, **kw)
            for k in range(steps):
                if k == 40 and i in (1, 4):
                    one.reset(np.ones(4), 2 * np.eye(4))
                one.predict(us[k, i:i + 1])
                x, P = one.update(ys[k, i:i + 1], masks[k, i:i + 1])
                np.testing.assert_allclose(x[0], est[k][i], atol=1e-10, rtol=0)
            np.testing.assert_allclose(P[0], many.P[i], atol=1e-10, rtol=0)


def test_missing_channel_gets_no_gain_and_nan_is_missing():
    F, G, H, Q, R = system()
    a = KalmanFilter(F, G, H, Q, R, dt=0.1)
    b = KalmanFilter(F, G, H, Q, R, dt=0.1)
    H1 = H[:1]
    c = KalmanFilter(F, G, H1, Q, R[:1, :1], dt=0.1)
    for f in (a, b, c):
        f.predict([[0.5]])
    a.update([[0.3, np.nan]])
    b.update([[0.3, 123.0]], mask=[[True, False]])
    c.update([[0.3]])
    for f in (a, b):
        np.testing.assert_allclose(f.x, c.x, atol=1e-14)
        np.testing.assert_allclose(f.P, c.P, atol=1e-14)
        assert np.isfinite(f.x).all()


@pytest.mark.parametrize("dropout", [0.0, 0.1])
def test_covariance_stays_symmetric_positive_definite_in_float32(dropout):
    """Badly scaled states (1e3 and 1e-3) and a nearly unobservable mode, 20 000 steps; with
    dropout each filter holds its own covariance (the compiled kernels), else they share one."""
    A = np.array([[0, 1, 0], [0, -1e-3, 0], [0, 0, -1e-4]])
    F, G = zoh(A, np.array([[0.0], [1.0], [0.0]]), 0.1)
    H = np.array([[1.0, 0, 1e-4]])
    Q = np.diag([1e2, 1e-6, 1e-10])
    kf = KalmanFilter(F, G, H, Q, [[1e-4]], dt=0.1, dtype=np.float32, batch_size=2,
                      P0=np.diag([1e6, 1.0, 1e-6]))
    rng = np.random.default_rng(8)
    masks = rng.random((20000, 2, 1)) >= dropout
    lowest, per_filter = np.inf, 0
    for k in range(20000):
        kf.predict(np.zeros((2, 1)))
        kf.update(rng.normal(size=(2, 1)) * 1e3, masks[k])
        per_filter += not kf.shared_covariance
        if k % 500 == 0:
            lowest = min(lowest, np.linalg.eigvalsh(kf.P.astype(float)).min())
            assert np.array_equal(kf.P, kf.P.transpose(0, 2, 1))
    assert kf.x.dtype == np.float32 and lowest > 0 and np.isfinite(kf.x).all()
    assert per_filter > 10000 if dropout else per_filter == 0


@pytest.mark.parametrize("per_filter", [True, False])
def test_diverging_filter_is_flagged_and_reinitialised_on_request(per_filter):
    F, G, H, Q, R = system()
    xs, us, ys = simulate(F, G, H, Q, R, 100, 2, seed=9)
    ys[60:, 1] += 50.0  # filter 1's sensor jumps: its innovations explode
    masks = np.ones((100, 2, 2), dtype=bool)
    masks[::7, 0, 1] = not per_filter  # a missing channel now and then: a covariance each
    for reinit in (False, True):
        kf = KalmanFilter(F, G, H, Q, R, dt=0.1, batch_size=2, reinitialise_diverged=reinit)
        flagged = []
        for k in range(100):
            kf.predict(us[k])
            kf.update(ys[k], masks[k])
            flagged.append(kf.diverged.copy())
        flagged = np.array(flagged)
        assert not flagged[:60].any() and not flagged[:, 0].any()
        assert flagged[-1, 1]
        assert np.isfinite(kf.x).all()


def test_a_covariance_that_overflows_is_flagged_not_left_as_silent_nan():
    """An unstable model with no measurements: the covariance of filter 1 overflows float32 and
    turns NaN; the filter is flagged diverged (and restarted on request), filter 0 is not."""
    F = np.diag([1.5, 1.2])
    for reinit in (False, True):
        kf = KalmanFilter(F, np.zeros((2, 1)), np.eye(2), np.eye(2), np.eye(2), dt=0.1,
                          batch_size=2, dtype=np.float32, reinitialise_diverged=reinit)
        mask = np.array([[True, True], [False, False]])
        for _ in range(300):
            kf.predict(np.zeros((2, 1)))
            kf.update(np.zeros((2, 2)), mask)
        assert kf.diverged.tolist() == [False, True]
        assert np.isfinite(kf.P[0]).all() and np.isfinite(kf.x[0]).all()
        assert np.isfinite(kf.P[1]).all() == np.isfinite(kf.x[1]).all() == reinit


def _random_system(rng, n, m):
    """A stable (spectral radius 0.95) system with full noise covariances."""
    A = rng.normal(size=(n, n))
    F = 0.95 * A / np.abs(np.linalg.eigvals(A)).max()
    L, M = rng.normal(size=(n, n)), rng.normal(size=(m, m))
    Q, R = 0.01 * (L @ L.T / n + np.eye(n)), 0.1 * (M @ M.T / m + np.eye(m))
    return F, rng.normal(size=(n, 2)), rng.normal(size=(m, n)), Q, R


def _relative_gap(a, b, scale=None):
    """Largest |a - b| of each filter over its ``scale`` (default: the largest |b| of that
    filter), the worst filter."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    axes = tuple(range(1, a.ndim))
    scale = np.abs(b).max(axis=axes) if scale is None else scale
    gap = np.abs(a - b).max(axis=axes) if axes else np.abs(a - b)
    return float((gap / np.maximum(scale, np.finfo(float).tiny)).max())


#: The exactness scenarios: ``(n, m, angular, seed, adaptive, dropout)``; with dropout some
#: filters miss channels (a covariance each), without it the filters share one covariance but
#: for the resets of a few (split, then merged again).
SCENARIOS = {"kf_5x4": (5, 4, (), 11, False, True), "akf_3x2_angle": (3, 2, (1,), 12, True, True),
             "kf_4x1_angle": (4, 1, (0,), 13, False, True),
             "akf_4x1_angle": (4, 1, (0,), 13, True, True),
             "kf_shared_4x2": (4, 2, (), 14, False, False)}
FILTERS, STEPS, EVERY = 6, 80, 10  # covariances recorded every EVERY steps


def run_scenario(case, reference=False):
    """A random system (``_random_system``) filtered with random dropout (some filters missing
    every channel at times), NaN measurements, angles measured off by whole turns and resets of
    random filters (some to their own x0 and P0); what each step gave. ``reference``: the numpy
    path of commit b31a8e0 (``tests/data/make_kalman_reference.py``)."""
    n, m, angular, seed, adaptive, dropout = case
    rng = np.random.default_rng(seed)
    F, G, H, Q, R = _random_system(rng, n, m)
    N = FILTERS
    kw = {"Q_max": 10 * Q} if adaptive else {}
    cls = AdaptiveKalmanFilter if adaptive else KalmanFilter
    kf = cls(F, G, H, Q, R, dt=0.1, batch_size=N, angular=angular, P0=np.eye(n), **kw)
    if reference:
        kf.run_in_numpy()
    x = rng.normal(size=(N, n))
    out = {k: [] for k in ("x", "innovation", "nis", "dof", "diverged", "shared", "P_pred", "P",
                           "S", "high", "fired")}
    for k in range(STEPS):
        if k % 37 == 20:  # restart a few filters, from defaults or from their own x0 and P0
            idx = rng.choice(N, 2, replace=False)
            x0, P0 = rng.normal(size=(2, n)), 2 * np.eye(n) + 0.1 * np.ones((n, n))
            kf.reset(x0, P0, idx=idx) if k % 2 else kf.reset(idx=idx)
        u = rng.normal(size=(N, 2))
        x = x @ F.T + u @ G.T + rng.multivariate_normal(np.zeros(n), Q, N)
        y = x @ H.T + rng.multivariate_normal(np.zeros(m), R, N)
        y[:, list(angular)] += 2 * np.pi * rng.integers(-2, 3, size=(N, len(angular)))
        mask = None
        if dropout:
            mask = rng.random((N, m)) >= (0.15 if k % 10 < 7 else 0.0)  # dropout, then none
            mask[rng.random(N) < 0.05] = False  # nothing measured
            y[rng.random((N, m)) < 0.02] = np.nan  # missing too
        kf.predict(u)
        if k % EVERY == EVERY - 1:
            out["P_pred"].append(np.array(kf.P))
        kf.update(y, mask)
        if k % EVERY == EVERY - 1:
            out["P"].append(np.array(kf.P))
            out["S"].append(np.array(kf.innovation_cov))
        for name in ("x", "innovation", "nis", "dof", "diverged"):
            out[name].append(np.array(getattr(kf, name)))
        out["shared"].append(kf.shared_covariance)
        for name in ("high", "fired"):
            out[name].append(np.array(getattr(kf, name, np.zeros(N, dtype=bool))))
    return {k: np.array(v) for k, v in out.items()}


#: The numpy path of commit b31a8e0 on :data:`SCENARIOS` (tests/data/make_kalman_reference.py)
REFERENCE = Path(__file__).parent / "data" / "kalman_reference.npz"


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_the_compiled_filter_gives_the_recorded_numpy_numbers_at_every_step(name):
    """x, the innovation and its statistic at every step, the predicted and updated covariance
    and the innovation covariance every tenth, to 1e-12 relative (each filter to its largest
    entry; the innovation to the size of the measurement; the statistic to 1 + itself); every
    flag, the degrees of freedom and whether the covariance is shared exactly."""
    got = run_scenario(SCENARIOS[name])
    with np.load(REFERENCE) as data:
        ref = {k: data[f"{name}/{k}"] for k in got}
    for k in ("dof", "diverged", "shared", "high", "fired"):
        np.testing.assert_array_equal(got[k], ref[k], err_msg=k)
    worst = {}
    for k in ("x", "P_pred", "P", "S"):
        worst[k] = max(_relative_gap(a, b) for a, b in zip(got[k], ref[k], strict=True))
    seen = np.maximum(np.abs(ref["x"]).max(axis=2), 1.0)  # innovations: y - H x, of that size
    worst["innovation"] = max(_relative_gap(a, b, s) for a, b, s in
                              zip(got["innovation"], ref["innovation"], seen, strict=True))
    worst["nis"] = float((np.abs(got["nis"] - ref["nis"]) / (1 + ref["nis"])).max())
    assert max(worst.values()) <= 1e-12, worst
    assert np.abs(got["x"] - ref["x"]).max() > 0 or not SCENARIOS[name][5]  # not a copy


def test_pickled_filter_continues_exactly():
    F, G, H, Q, R = system()
    xs, us, ys = simulate(F, G, H, Q, R, 20, 3, seed=15)
    kf = AdaptiveKalmanFilter(F, G, H, Q, R, Q_max=5 * Q, dt=0.1, batch_size=3)
    run(kf, us[:10], ys[:10])
    copy = pickle.loads(pickle.dumps(kf))
    assert copy.compiled
    for f in (kf, copy):
        run(f, us[10:], ys[10:])
    np.testing.assert_array_equal(copy.x, kf.x)
    np.testing.assert_array_equal(copy.P, kf.P)


@pytest.mark.parametrize("kwargs, message", [
    ({"F": np.eye(3)}, "shapes do not match"),
    ({"H": np.ones((2, 3))}, "shapes do not match"),
    ({"Q": -np.eye(4)}, "Q is not positive semi-definite"),
    ({"Q": np.ones((4, 4)) + np.triu(np.ones((4, 4)))}, "Q is not symmetric"),
    ({"R": np.zeros((2, 2))}, "R must be positive definite"),
    ({"R": np.eye(3)}, "R has shape"),
    ({"P0": np.full((4, 4), np.nan)}, "P0 has non-finite"),
    ({"dt": 0.0}, "dt=0.0 is invalid"),
])
def test_bad_matrices_are_refused_by_name(kwargs, message):
    F, G, H, Q, R = system()
    args = {"F": F, "G": G, "H": H, "Q": Q, "R": R, "dt": 0.1, **kwargs}
    with pytest.raises(ValueError, match=message):
        KalmanFilter(**args)


def test_bad_step_inputs_are_refused():
    F, G, H, Q, R = system()
    kf = KalmanFilter(F, G, H, Q, R, dt=0.1, batch_size=3)
    with pytest.raises(ValueError, match=r"y has shape \(2, 2\)"):
        kf.update(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="u has shape"):
        kf.predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="x0 must be"):
        kf.reset([np.nan] * 4)
    with pytest.raises(ValueError, match="quantiles"):
        AdaptiveKalmanFilter(F, G, H, Q, R, Q_max=Q, dt=0.1, upper_quantile=0.3)


def test_from_model_keeps_absolute_units_at_a_trim_point():
    """The hydrofoil's KF predicts in absolute units: at trim with trim input it stays there."""
    craft = get_model("hydrofoil")
    kf = KalmanFilter.from_model(craft, 0.05, measured=craft.state_names, Q=1e-6 * np.eye(4),
                                 R=0.003 * np.eye(4))
    for _ in range(100):
        kf.predict(craft.u0)
    np.testing.assert_allclose(kf.x[0], craft.x0, atol=1e-9)
    A, B, _ = craft.linearize()
    Phi, _ = zoh(A, B, 0.05)
    np.testing.assert_allclose(kf.F, Phi)


def test_dp_vessel_filter_measures_low_plus_wave_frequency_motion():
    """Outputs that are not states (north = LF + WF) get the right measurement matrix."""
    ship = get_model("dp_vessel")
    kf = KalmanFilter.from_model(ship, 0.5, measured=("north", "east", "psi"),
                                 Q=np.eye(15) * 1e-6, R=np.eye(3))
    rng = np.random.default_rng(10)
    x = ship.x0 + rng.normal(size=15)
    np.testing.assert_allclose(x @ kf.H.T + kf.d, ship.output(x[None])[0][
        [ship.output_names.index(c) for c in ("north", "east", "psi")]], atol=1e-6)
