"""Kalman-filter throughput and numerical checks against filterpy, in one run on one core.

Measured: filter-updates per second, i.e. ``predict`` + ``update`` pairs times the batch size
``N`` over the wall time, of a fixed seeded stable 5-state / 4-measurement / 1-input system on
data simulated from it. Rows:

* filterpy's ``KalmanFilter``, one filter in a Python loop (the reference, ratio 1);
* ours with ``N=1`` in the same loop;
* ours with ``N=256`` (the size of issue 23) and ``N=1024``: every channel measured (one
  covariance shared by the batch), 10% random dropout masks (a covariance per filter), the
  adaptive filter (process noise switching per filter) and float32.

Absolute rates on shared machines are noise; the ratios to filterpy measured in the same run are
the numbers to compare (a ratio of 100 = a hundred filters updated in the time filterpy updates
one). Each figure is the best of interleaved repeats. BLAS threads are limited to one
(threadpoolctl) and the process is pinned to one CPU.

Targets (printed, never failing the run): ``KalmanFilter`` at ``N=1024`` >= 1e6 updates/s
(issue 4); the dropout and adaptive rows at ``N=256`` >= 45 times filterpy (issue 23).

Checks, printed in the same run (exit code 1 when one fails; a missed speed target only prints
MISSED): (a) a batch of 1024 with dropout and mid-run resets of some rows gives, for a subset of
rows, the x and P of each row's filter run alone, within 1e-10; (b) ours with ``N=1`` gives
filterpy's x and P within 1e-10; (c) float32 on an ill-conditioned system keeps every predicted
and updated P symmetric and positive definite at every step, in a batch of 1000 filters x 1000
steps and in one filter run sequentially; (d) a batch measured on every channel, whose
covariance is shared (its step done once), gives at every step the x and P of its filters run
alone within 1e-12 relative (to each filter's largest entry), for both filters. (The kernels
against the numpy code they replaced: ``tests/test_kalman.py``, on recorded numbers.)

    python benchmarks/estimator_throughput.py [--quick] [--repeats 3] [--sequential-steps 500000]
                                             [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from typing import TYPE_CHECKING  # noqa: E402

import numpy as np  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path, pin_to_one_cpu  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from estimators.kalman import AdaptiveKalmanFilter, KalmanFilter  # noqa: E402
from marine_envs.files import write_json  # noqa: E402

if TYPE_CHECKING:
    from filterpy.kalman import KalmanFilter as FilterpyKF

N_X, N_Y, N_U = 5, 4, 1
BATCH = 1024
#: batch sizes of the table: the size of issue 23's targets, then :data:`BATCH`
BATCHES = (256, BATCH)
DROPOUT = 0.1
TOLERANCE = 1e-10
#: a shared covariance's step vs the filters' own, relative to each filter's largest |x| or |P|
EXACTNESS = 1e-12
#: minimum filter-updates per second, by (row label, N) (issue 4)
TARGETS = {("KalmanFilter", BATCH): 1e6}
#: minimum ratio to filterpy in the same run, by (row label, N) (issue 23)
RATIO_TARGETS = {("KalmanFilter, 10% dropout", 256): 45.0, ("AdaptiveKalmanFilter", 256): 45.0}
FILTERPY_LABEL = "filterpy KalmanFilter"
TITLE = "Kalman-filter throughput"
ABOUT = """\
Filter-updates per second (`predict` + `update` pairs times the batch size N, over the wall
time) of `estimators.kalman.KalmanFilter` and `AdaptiveKalmanFilter` on a fixed seeded stable
5-state, 4-measurement, 1-input system, against filterpy's `KalmanFilter` (one filter in a
Python loop) measured in the same run: the ratio column is the result (a ratio of 100: a
hundred filters updated in the time filterpy updates one), absolute rates on a shared machine
are not. Rows at N = 1, and at N = 256 and 1024 with every channel measured (one covariance
for the batch), 10 % random dropout (a covariance per filter), the adaptive filter and float32.
Each figure is the best of interleaved repeats, on one BLAS thread and one CPU. The checks
below the table are numerical: a batch equals its filters run alone, N = 1 equals filterpy,
filters sharing one covariance equal their filters run alone, float32 covariances stay
symmetric positive definite on an ill-conditioned system."""

Array = NDArray[np.float64]


@dataclass(frozen=True)
class System:
    """``x' = F x + G u + w``, ``y = H x + v`` with ``w ~ N(0, Q)``, ``v ~ N(0, R)``, and
    ``x0 ~ N(0, P0)``."""

    F: Array
    G: Array
    H: Array
    Q: Array
    R: Array
    P0: Array
    dt: float = 0.1


def _random_covariance(rng: np.random.Generator, n: int, scale: float) -> Array:
    L = rng.normal(size=(n, n))
    C = scale * (L @ L.T / n + np.eye(n))
    return (C + C.T) / 2


def random_system(seed: int = 0) -> System:
    """A seeded stable (spectral radius 0.95), observable system with full noise covariances."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N_X, N_X))
    F = 0.95 * A / np.abs(np.linalg.eigvals(A)).max()
    return System(F=F, G=rng.normal(size=(N_X, N_U)), H=rng.normal(size=(N_Y, N_X)),
                  Q=_random_covariance(rng, N_X, 0.01), R=_random_covariance(rng, N_Y, 0.1),
                  P0=np.eye(N_X))


def ill_conditioned_system() -> System:
    """Heading, yaw rate, gyro bias, position and speed of a vessel (dt = 0.1 s).

    The scales span 1e-6 rad/s to 10 m, a precise gyro measures rate plus bias, so the two are
    strongly correlated and the bias (a near-unit-root mode) is only weakly observable through
    the noisy compass: the covariance's condition number reaches ~1e12, far beyond float32's
    1/eps ~ 1e7.
    """
    dt = 0.1
    F = np.eye(N_X)
    F[0, 1], F[1, 1], F[2, 2], F[3, 4], F[4, 4] = dt, 0.98, 1 - 1e-5, dt, 0.999
    H = np.array([[1.0, 0, 0, 0, 0], [0, 1, 1, 0, 0], [0, 0, 0, 1, 0], [0, 0, 0, 0, 1]])
    return System(F=F, G=np.array([[0], [0.005], [0], [0], [0.01]]), H=H,
                  Q=np.diag([1e-8, 1e-6, 1e-16, 1e-4, 1e-3]),
                  R=np.diag([0.02**2, 1e-5**2, 2.0**2, 0.05**2]),
                  P0=np.diag([0.1**2, 0.01**2, 1e-3**2, 10.0**2, 1.0**2]), dt=dt)


def simulate(system: System, steps: int, batch: int,
             rng: np.random.Generator) -> tuple[Array, Array]:
    """Inputs ``u`` ``(steps, batch, 1)`` and measurements ``y`` ``(steps, batch, 4)`` of
    ``batch`` independent runs of the system (white Gaussian inputs)."""
    n, m = system.H.shape[1], system.H.shape[0]
    Lq, Lr, L0 = (np.linalg.cholesky(system.Q), np.linalg.cholesky(system.R),
                  np.linalg.cholesky(system.P0))
    x = rng.normal(size=(batch, n)) @ L0.T
    u = rng.normal(size=(steps, batch, N_U))
    y = np.empty((steps, batch, m))
    for k in range(steps):
        x = x @ system.F.T + u[k] @ system.G.T + rng.normal(size=(batch, n)) @ Lq.T
        y[k] = x @ system.H.T + rng.normal(size=(batch, m)) @ Lr.T
    return u, y


def dropout(steps: int, batch: int, rng: np.random.Generator) -> NDArray[np.bool_]:
    """Masks ``(steps, batch, 4)``: each channel missing with probability 10%."""
    return rng.random((steps, batch, N_Y)) >= DROPOUT


def make_filter(system: System, batch: int, *, adaptive: bool = False,
                dtype: type = np.float64) -> KalmanFilter:
    """Our filter of ``system``; the adaptive one switches to ``Q_max = 10 Q``."""
    kwargs = dict(dt=system.dt, P0=system.P0, batch_size=batch, dtype=dtype)
    if adaptive:
        return AdaptiveKalmanFilter(system.F, system.G, system.H, system.Q, system.R,
                                    Q_max=10 * system.Q, **kwargs)
    return KalmanFilter(system.F, system.G, system.H, system.Q, system.R, **kwargs)


def make_filterpy(system: System) -> FilterpyKF:
    """filterpy's filter of ``system``, started like ours (x = 0, P = P0)."""
    from filterpy.kalman import KalmanFilter as FilterpyKF

    f = FilterpyKF(dim_x=N_X, dim_z=N_Y, dim_u=N_U)
    f.F, f.B, f.H = system.F.copy(), system.G.copy(), system.H.copy()
    f.Q, f.R, f.P = system.Q.copy(), system.R.copy(), system.P0.copy()
    return f


# -- throughput -------------------------------------------------------------------------------
@dataclass
class Case:
    """A row of the table: ``run()`` replays the data once and returns the seconds it took."""

    label: str
    batch: int
    run: Callable[[], float]
    path: Callable[[], str]


def our_case(label: str, kf: KalmanFilter, u: Array, y: Array,
             mask: NDArray[np.bool_] | None = None) -> Case:
    def run() -> float:
        kf.reset()
        start = time.perf_counter()
        for k in range(len(u)):
            kf.predict(u[k])
            kf.update(y[k], None if mask is None else mask[k])
        return time.perf_counter() - start

    def path() -> str:
        if kf.batch_size == 1:
            return "loop"
        return "shared P" if kf.shared_covariance else "per-filter P"

    return Case(label, kf.batch_size, run, path)


def filterpy_case(system: System, u: Array, y: Array) -> Case:
    f = make_filterpy(system)

    def run() -> float:
        f.x, f.P = np.zeros((N_X, 1)), system.P0.copy()
        start = time.perf_counter()
        for k in range(len(u)):
            f.predict(u=u[k].reshape(N_U, 1))
            f.update(y[k, 0])
        return time.perf_counter() - start

    return Case(FILTERPY_LABEL, 1, run, lambda: "loop")


def build_cases(system: System, steps: dict[int, int],
                rng: np.random.Generator) -> list[Case]:
    """The rows, filterpy first (the reference), then ours at ``N=1`` and at each of
    :data:`BATCHES`; ``steps`` by N. Rows of the same N replay the same data."""
    u1, y1 = simulate(system, steps[1], 1, rng)
    cases = [filterpy_case(system, u1, y1),
             our_case("KalmanFilter", make_filter(system, 1), u1, y1)]
    for batch in BATCHES:
        u, y = simulate(system, steps[batch], batch, rng)
        mask = dropout(steps[batch], batch, rng)
        cases += [
            our_case("KalmanFilter", make_filter(system, batch), u, y),
            our_case("KalmanFilter, 10% dropout", make_filter(system, batch), u, y, mask),
            our_case("AdaptiveKalmanFilter", make_filter(system, batch, adaptive=True), u, y),
            our_case("KalmanFilter float32", make_filter(system, batch, dtype=np.float32),
                     u.astype(np.float32), y.astype(np.float32)),
        ]
    return cases


def table_steps(quick: bool) -> dict[int, int]:
    """Steps replayed by each N: about the same number of filter updates at every batch size."""
    single, batch = (1000, 100) if quick else (4000, 300)
    return {1: single, **{n: batch * BATCH // n for n in BATCHES}}


def measure(cases: list[Case], steps: dict[int, int], repeats: int) -> list[dict]:
    """Rows ``{filter, N, path, steps, updates_per_s, ratio}``: best of ``repeats`` interleaved
    runs, ratio to the first case (filterpy)."""
    best = [0.0] * len(cases)
    for _ in range(repeats):
        for i, case in enumerate(cases):
            best[i] = max(best[i], steps[case.batch] * case.batch / case.run())
    return [{"filter": case.label, "N": case.batch, "path": case.path(),
             "steps": steps[case.batch], "updates_per_s": rate, "ratio": rate / best[0]}
            for case, rate in zip(cases, best, strict=True)]


def target_status(row: dict) -> str:
    """The row's target and whether it was met, or "" when it has none."""
    key = (row["filter"], row["N"])
    if key in TARGETS:
        target = TARGETS[key]
        return f">= {target:.0e}/s " + ("ok" if row["updates_per_s"] >= target else "MISSED")
    if key in RATIO_TARGETS:
        target = RATIO_TARGETS[key]
        return f">= {target:.0f}x " + ("ok" if row["ratio"] >= target else "MISSED")
    return ""


def format_table(rows: list[dict]) -> str:
    lines = [f"{'filter':<28}{'N':>6}  {'path':<14}{'updates/s':>13}{'ratio':>9}  target"]
    for row in rows:
        lines.append(f"{row['filter']:<28}{row['N']:>6}  {row['path']:<14}"
                     f"{row['updates_per_s']:>13,.0f}{row['ratio']:>9.2f}  {target_status(row)}")
    return "\n".join(lines)


# -- correctness ------------------------------------------------------------------------------
def batch_vs_single(system: System, *, adaptive: bool, batch: int = BATCH, steps: int = 200,
                    rows: int = 32, seed: int = 1) -> dict:
    """Max |x - x_alone| and |P - P_alone| over every step, for ``rows`` rows of a batch run with
    dropout masks and two resets of some rows (a quarter of the checked rows among them)."""
    rng = np.random.default_rng(seed)
    u, y = simulate(system, steps, batch, rng)
    mask = dropout(steps, batch, rng)
    checked = np.sort(rng.choice(batch, rows, replace=False))
    resets = {}  # step -> (rows, x0 per row, P0 or None)
    for k, P0 in ((steps * 3 // 10, None), (steps * 13 // 20, 2 * system.P0)):
        some = checked[rng.random(rows) < 0.25]
        idx = np.union1d(rng.choice(batch, batch // 8, replace=False), some)
        resets[k] = (idx, rng.normal(size=(idx.size, N_X)), P0)

    def run(kf: KalmanFilter, take: NDArray[np.intp]) -> tuple[Array, Array]:
        xs, Ps = [], []
        for k in range(steps):
            if k in resets:
                idx, x0, P0 = resets[k]
                hit = np.isin(idx, take)
                if kf.batch_size == 1 and hit.any():
                    kf.reset(x0[hit][0], P0)
                elif kf.batch_size > 1:
                    kf.reset(x0, P0, idx=idx)
            kf.predict(u[k][take])
            x, P = kf.update(y[k][take], mask[k][take])
            sel = slice(None) if kf.batch_size == 1 else checked
            xs.append(x[sel].copy())
            Ps.append(np.array(P[sel]))
        return np.array(xs), np.array(Ps)

    xb, Pb = run(make_filter(system, batch, adaptive=adaptive), np.arange(batch))
    alone = [run(make_filter(system, 1, adaptive=adaptive), np.array([r])) for r in checked]
    xa = np.concatenate([a[0] for a in alone], axis=1)
    Pa = np.concatenate([a[1] for a in alone], axis=1)
    err_x, err_P = float(np.abs(xb - xa).max()), float(np.abs(Pb - Pa).max())
    name = "AdaptiveKalmanFilter" if adaptive else "KalmanFilter"
    return {"check": f"{name} N={batch} vs alone", "passed": max(err_x, err_P) <= TOLERANCE,
            "detail": f"{rows} rows x {steps} steps, dropout + 2 resets: "
                      f"max|dx| {err_x:.1e}, max|dP| {err_P:.1e} (<= {TOLERANCE:.0e})",
            "max_abs_x": err_x, "max_abs_P": err_P}


def _relative_gap(a: NDArray, b: NDArray) -> float:
    """Largest |a - b| of a filter over its largest |b|, the worst filter."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    axes = tuple(range(1, a.ndim))
    scale = np.maximum(np.abs(b).max(axis=axes), np.finfo(float).tiny)
    return float((np.abs(a - b).max(axis=axes) / scale).max())


def shared_vs_alone(system: System, *, adaptive: bool, batch: int = 256, steps: int = 200,
                    rows: int = 8, seed: int = 5) -> dict:
    """Largest relative gap of x and P (predicted and updated) at every step between a batch
    measured on every channel (one covariance shared by the batch, its step done once by the
    kernels) and ``rows`` of its filters run alone."""
    rng = np.random.default_rng(seed)
    u, y = simulate(system, steps, batch, rng)
    checked = np.sort(rng.choice(batch, rows, replace=False))
    together = make_filter(system, batch, adaptive=adaptive)
    alone = [make_filter(system, 1, adaptive=adaptive) for _ in checked]
    gap_x = gap_P = 0.0
    shared = 0
    for k in range(steps):
        together.predict(u[k])
        for f, r in zip(alone, checked, strict=True):
            f.predict(u[k][r:r + 1])
        P_alone = np.concatenate([f.P for f in alone])
        gap_P = max(gap_P, _relative_gap(together.P[checked], P_alone))
        together.update(y[k])
        shared += together.shared_covariance
        for f, r in zip(alone, checked, strict=True):
            f.update(y[k][r:r + 1])
        x_alone, P_alone = (np.concatenate([getattr(f, a) for f in alone]) for a in ("x", "P"))
        gap_x = max(gap_x, _relative_gap(together.x[checked], x_alone))
        gap_P = max(gap_P, _relative_gap(together.P[checked], P_alone))
    name = "AdaptiveKalmanFilter" if adaptive else "KalmanFilter"
    return {"check": f"{name} N={batch} shared P vs alone",
            "passed": max(gap_x, gap_P) <= EXACTNESS,
            "detail": f"{steps} steps, P shared at {shared} of them: max relative gap x "
                      f"{gap_x:.1e}, P {gap_P:.1e} (<= {EXACTNESS:.0e})",
            "max_rel_x": gap_x, "max_rel_P": gap_P}


def ours_vs_filterpy(system: System, steps: int = 500, seed: int = 2) -> dict:
    """Max |x - x_filterpy| and |P - P_filterpy| over every step of one filter."""
    u, y = simulate(system, steps, 1, np.random.default_rng(seed))
    kf, f = make_filter(system, 1), make_filterpy(system)
    err_x = err_P = 0.0
    for k in range(steps):
        kf.predict(u[k])
        x, P = kf.update(y[k])
        f.predict(u=u[k].reshape(N_U, 1))
        f.update(y[k, 0])
        err_x = max(err_x, float(np.abs(x[0] - f.x[:, 0]).max()))
        err_P = max(err_P, float(np.abs(P[0] - f.P).max()))
    return {"check": "KalmanFilter N=1 vs filterpy", "passed": max(err_x, err_P) <= TOLERANCE,
            "detail": f"{steps} steps: max|dx| {err_x:.1e}, max|dP| {err_P:.1e} "
                      f"(<= {TOLERANCE:.0e})", "max_abs_x": err_x, "max_abs_P": err_P}


@dataclass
class Health:
    """Running worst case of a stream of covariances."""

    min_corr_eig: float = np.inf  # of D^-1/2 P D^-1/2: > 0 iff P is positive definite
    min_eig_ratio: float = np.inf  # smallest over largest eigenvalue of P
    max_asymmetry: float = 0.0  # max |P - P'| / max |P|
    count: int = 0
    diverged: int = 0

    def add(self, P: NDArray[np.floating]) -> None:
        """Fold in a stack of covariances ``(..., n, n)`` (computed in float64)."""
        P = np.asarray(P, dtype=np.float64).reshape(-1, N_X, N_X)
        scale = np.abs(P).max(axis=(1, 2))
        self.max_asymmetry = max(self.max_asymmetry, float(
            (np.abs(P - P.transpose(0, 2, 1)).max(axis=(1, 2)) / scale).max()))
        eig = np.linalg.eigvalsh(P)
        self.min_eig_ratio = min(self.min_eig_ratio, float((eig[:, 0] / eig[:, -1]).min()))
        d = np.diagonal(P, axis1=1, axis2=2)
        if not (np.isfinite(P).all() and (d > 0).all()):
            self.min_corr_eig = -np.inf
        else:
            s = 1 / np.sqrt(d)
            corr = np.linalg.eigvalsh(P * s[:, :, None] * s[:, None, :])[:, 0].min()
            self.min_corr_eig = min(self.min_corr_eig, float(corr))
        self.count += P.shape[0]

    @property
    def passed(self) -> bool:
        return bool(self.min_corr_eig > 0
                    and self.max_asymmetry <= 4 * np.finfo(np.float32).eps)

    def fields(self) -> dict:
        return {"min_corr_eig": self.min_corr_eig, "min_eig_ratio": self.min_eig_ratio,
                "max_asymmetry": self.max_asymmetry, "covariances": self.count,
                "diverged": self.diverged}

    def summary(self) -> str:
        return (f"{self.count:,} covariances (predicted and updated): min eig of corr(P) "
                f"{self.min_corr_eig:.2e}, min eig/max eig {self.min_eig_ratio:.1e}, "
                f"max asymmetry {self.max_asymmetry:.1e}, diverged flags {self.diverged}")


def float32_batch(filters: int, steps: int, seed: int = 3) -> dict:
    """``filters`` float32 filters of the ill-conditioned system with dropout (so each has its own
    covariance), every predicted and updated P checked at every step."""
    system = ill_conditioned_system()
    rng = np.random.default_rng(seed)
    u, y = simulate(system, steps, filters, rng)
    u, y = u.astype(np.float32), y.astype(np.float32)
    mask = dropout(steps, filters, rng)
    kf, health = make_filter(system, filters, dtype=np.float32), Health()
    for k in range(steps):
        kf.predict(u[k])
        health.add(kf.P)
        health.add(kf.update(y[k], mask[k])[1])
    health.diverged = int(kf.diverged.sum())
    return {"check": f"float32 batch {filters} x {steps} steps",
            "passed": health.passed, "detail": f"{filters * steps:,} filter steps, "
            + health.summary(), "filter_steps": filters * steps, **health.fields()}


def float32_sequential(steps: int, seed: int = 4, chunk: int = 1000) -> dict:
    """One float32 filter of the ill-conditioned system, ``steps`` sequential predict/update pairs
    with dropout; each P is buffered and checked ``chunk`` at a time (so every step is checked)."""
    system = ill_conditioned_system()
    rng = np.random.default_rng(seed)
    u, y = simulate(system, steps, 1, rng)
    u, y = u.astype(np.float32), y.astype(np.float32)
    mask = dropout(steps, 1, rng)
    kf, health = make_filter(system, 1, dtype=np.float32), Health()
    buffer = np.empty((chunk, 2, N_X, N_X), dtype=np.float32)
    start = time.perf_counter()
    for k in range(steps):
        kf.predict(u[k])
        buffer[k % chunk, 0] = kf.P[0]
        buffer[k % chunk, 1] = kf.update(y[k], mask[k])[1][0]
        if k % chunk == chunk - 1 or k == steps - 1:
            health.add(buffer[:k % chunk + 1])
    seconds = time.perf_counter() - start
    health.diverged = int(kf.diverged.sum())
    return {"check": f"float32 sequential 1 x {steps} steps", "passed": health.passed,
            "detail": f"{steps:,} filter steps in {seconds:.0f} s, " + health.summary(),
            "filter_steps": steps, "seconds": seconds, **health.fields()}


# -- the run ----------------------------------------------------------------------------------
def run_checks(quick: bool, sequential_steps: int) -> list[dict]:
    system = random_system()
    steps = 60 if quick else 200
    checks = [batch_vs_single(system, adaptive=False, steps=steps),
              batch_vs_single(system, adaptive=True, steps=steps),
              ours_vs_filterpy(system),
              shared_vs_alone(system, adaptive=False, steps=steps),
              shared_vs_alone(system, adaptive=True, steps=steps)]
    checks.append(float32_batch(1000, 100 if quick else 1000))
    checks.append(float32_sequential(sequential_steps))
    return checks


def format_checks(checks: list[dict]) -> str:
    return "\n".join(f"{'pass' if c['passed'] else 'FAIL':<6}{c['check']:<46}{c['detail']}"
                     for c in checks)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="fewer steps everywhere (~10 s instead of ~2 min)")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats (3)")
    parser.add_argument("--sequential-steps", type=int,
                        help="steps of the sequential float32 run (500000; --quick 20000)")
    parser.add_argument("--json", help="also write the rows and checks as JSON")
    parser.add_argument("--table-only", action="store_true", help="skip the checks")
    add_docs_option(parser, "estimator_throughput")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    with benchmark_run("estimator_throughput", argv) as bench:
        pinned = pin_to_one_cpu()
        steps = table_steps(args.quick)
        sequential = args.sequential_steps or (20_000 if args.quick else 500_000)
        settings = {"numpy": np.__version__, "blas": bench.blas, "cpu": pinned,
                    "repeats": args.repeats, "quick": args.quick}
        print(f"numpy {np.__version__}, {pinned}; best of {args.repeats}; steps by N: {steps}")
        cases = build_cases(random_system(), steps, np.random.default_rng(0))
        rows = measure(cases, steps, args.repeats)
        bench.show(format_table(rows), f"Updates per second, best of {args.repeats}",
                   markdown=False)
        print()
        checks = [] if args.table_only else run_checks(args.quick, sequential)
        if checks:
            bench.show(format_checks(checks), "Checks", markdown=False)
    if args.json:
        targets = {f"{label} N={n}": value for (label, n), value in TARGETS.items()}
        ratio_targets = {f"{label} N={n}": value for (label, n), value in RATIO_TARGETS.items()}
        write_json(args.json, {"settings": settings, "rows": rows, "checks": checks,
                               "targets": targets, "ratio_targets": ratio_targets})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if all(c["passed"] for c in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
