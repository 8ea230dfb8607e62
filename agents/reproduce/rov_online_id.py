"""The morphing-robot patent: online identification of an ROV's viscous coefficients, feed-forward.

The patent (2022) runs a Kalman filter on the joint state ``[omega; nu]`` (the 18 viscous
coefficients and the velocities), with the DVL (u, v, w) and a fibre-optic gyro (attitude and
rates) as its only sensors and an ARTIFICIAL process noise on the coefficients so that the
estimates follow the morph from the cruise to the work shape; the identified coefficients feed a
thrust feed-forward. It gives no numbers, so this reproduction states its own experiment:

* Plant: ROV-v0 (Prestero's REMUS-100, docs/models.md 3), force actuation without a roll moment (the
  thrusters have none), still water (see "Current" below), sensors as ROV-v0 (DVL at 5 Hz, gyro
  and depth cell at 10 Hz). The morph command comes at ``morph_time``; the hull follows with
  T_m = 5 s.
* Filter: :class:`~estimators.ekf.ExtendedKalmanFilter` of the ROV model with the 18
  coefficients appended (:data:`~marine_envs.models.rov.SEED_COEFFICIENTS`); each is the value at
  the current shape (``ROVModel.rhs_with``), and the filter knows the morph command (the robot
  gives it), hence M(s), the CG shift and the restoring forces. Initial guesses are drawn from the
  prior (the cruise values plus a normal error of half a coefficient's scale), so that the values
  before the morph are identified, not given.
* Artificial noise: ``q_i = RATE * scale_i`` per sqrt(s), ``scale_i = max(|c_i|, floor_i)``, the
  floor being the value at which the term gives 0.5 N (N m; roll 0.05 N m) at a typical motion
  (1.5 m/s, 0.2 m/s, 0.2 rad/s): below it a coefficient does not matter for control, and a
  streamlined hull's near-zero coefficients (Yrr, Zqq, Kpp) may grow by far more than their own
  size when the arm comes out. ``RATE`` = 0.05 s^-1/2: without data, the random walk restores
  the prior uncertainty (half a scale) in (0.5 / 0.05)^2 = 100 s, so the filter remembers about a
  minute and a half of data and never saturates; where the data are rich (Xuu, Nrr) the gain this
  leaves follows a change within about 20 s (the hull itself takes 11 s). In a trial, 0.02
  halved the spread of the estimates but took 27 s for Xuu; 0.1 took 14 s but doubled the
  spread (Nrr +-7 %, close to the 10 % criterion).
* Excitation (the reference the robot flies, all sinusoids with incommensurate periods): speed
  0.9 +- 0.3 m/s (40 s), heading +-40 deg (15 s), sway 0.15 m/s (13 s), pitch +-4 deg (12 s) at
  constant angle of attack ``w = u tan(theta)`` plus depth +-0.3 m (15 s). It stays within the
  thrusters' box in both shapes (the work shape's 11.3 N m bow-down moment leaves 7.5 N m of
  pitch authority). It excites the surge and yaw drag, the sway and heave drag and the Munk and
  lift terms (u v, u w, u r) well. Roll is excited only by the turns (no roll authority; p about
  0.02-0.04 rad/s rms), so Kpp is weak; pitch rates of 0.03 rad/s rms leave q|q| in heave
  (Zqq: ~0.003 N) invisible and u q (Muq, Zuq) and v|v| in yaw (Nvv) weak.
* Control: :class:`agents.feedforward.FeedforwardTracker`, the discrete LQR of the cruise
  linearisation with integral action on speed, depth and heading, on the filter's state, plus
  inverse-dynamics feed-forward of the reference. Two fleets fly the same reference, filter and
  gains: ``feedforward`` uses the identified coefficients, ``nominal`` the cruise values.

Current: the DVL measures velocity over ground while the drag acts on the velocity through the
water; an unknown current would be read as drag. The patent does not estimate one, so
the experiment is in still water.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray
from tqdm.auto import tqdm

import marine_envs  # noqa: F401 - registers the environments
from agents.feedforward import ERROR_SCALES, FeedforwardTracker
from estimators.ekf import ExtendedKalmanFilter
from marine_envs.envs.rov import CHANNELS, DEFAULT_SENSORS
from marine_envs.models.rov import MORPHING, SEED_COEFFICIENTS, ROVModel
from marine_envs.provenance import save_figure

from .base import Reproduction, spread

FloatArray = NDArray[np.float64]
ENV_ID = "marine_envs/ROV-v0"
DEG = math.pi / 180
DT = 0.1
#: Random-walk intensity of each coefficient relative to its scale, 1/sqrt(s).
RATE = 0.05
#: Prior standard deviation relative to the scale.
PRIOR_FRACTION = 0.5
#: Typical motion [u v w p q r] (m/s, rad/s) and the force (N; N m) below which a term is
#: negligible for control, per force row; they set each coefficient's floor scale.
TYPICAL_MOTION = np.array([1.5, 0.2, 0.2, 0.2, 0.2, 0.2])
NEGLIGIBLE_FORCE = {"X": 0.5, "Y": 0.5, "Z": 0.5, "K": 0.05, "M": 0.5, "N": 0.5}
#: Force uncertainty per row of the filter's process noise (N, N m): the patent's R(tau).
FORCE_NOISE = np.array([0.5, 0.5, 0.5, 0.05, 0.1, 0.1])
#: Tracked coefficients (the surge and yaw quadratic drag) and the tolerance.
TRACKED = ("Xuu", "Nrr")
TOLERANCE = 0.10
#: Channels of the tracking error, with their Bryson scales (the controller's).
ERROR_CHANNELS = ("u", "v", "w", "z", "theta", "psi")
_STATE = ROVModel.state_names
_ERROR_INDEX = [_STATE.index(c) for c in ERROR_CHANNELS]
_ERROR_SCALE = np.array([ERROR_SCALES[c] for c in ERROR_CHANNELS])


@dataclasses.dataclass(frozen=True)
class Excitation:
    """The reference motion: sinusoids about straight, level flight at ``depth`` (m), heading
    north. Amplitudes in m/s, rad and m; periods in s."""

    speed: float = 0.9
    speed_amplitude: float = 0.3
    speed_period: float = 40.0
    heading_amplitude: float = 40 * DEG
    heading_period: float = 15.0
    sway_amplitude: float = 0.15
    sway_period: float = 13.0
    pitch_amplitude: float = 4 * DEG
    pitch_period: float = 12.0
    depth: float = 5.0
    depth_amplitude: float = 0.3
    depth_period: float = 15.0

    def motion(self, t: float) -> FloatArray:
        """``[u v w p q r z theta psi]`` at time ``t`` (s); roll and its rate are zero."""
        def wave(amplitude: float, period: float) -> tuple[float, float]:
            w = 2 * math.pi / period
            return amplitude * math.sin(w * t), amplitude * w * math.cos(w * t)

        u = self.speed + wave(self.speed_amplitude, self.speed_period)[0]
        psi, psi_dot = wave(self.heading_amplitude, self.heading_period)
        theta, theta_dot = wave(self.pitch_amplitude, self.pitch_period)
        dz, z_dot = wave(self.depth_amplitude, self.depth_period)
        v = wave(self.sway_amplitude, self.sway_period)[0]
        # level path: z_dot = -sin(theta) u + cos(theta) w (phi = 0); Euler rates with phi = 0
        w = (z_dot + math.sin(theta) * u) / math.cos(theta)
        q, r = theta_dot, psi_dot * math.cos(theta)
        return np.array([u, v, w, 0.0, q, r, self.depth + dz, theta, psi])

    def __call__(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Reference state (13,) with ``s = 0`` and body accelerations (6,) at ``t`` (s)."""
        m = self.motion(t)
        h = 1e-3  # central difference: the signals are smooth, the error is ~1e-7
        nu_dot = (self.motion(t + h)[:6] - self.motion(t - h)[:6]) / (2 * h)
        x = np.zeros(13)
        x[:6], x[8], x[10], x[11] = m[:6], m[6], m[7], m[8]
        return x, nu_dot


def coefficient_scales(model: ROVModel,
                       names: tuple[str, ...] = SEED_COEFFICIENTS) -> FloatArray:
    """``max(|c_i|, floor_i)``: each coefficient's cruise magnitude, or the value at which its term
    gives :data:`NEGLIGIBLE_FORCE` at :data:`TYPICAL_MOTION`, if larger (its unit)."""
    regressors = model.hydrodynamic_regressors(
        np.concatenate([TYPICAL_MOTION, np.zeros(7)]), names)  # (6, p), one term per column
    rows = np.abs(regressors).argmax(axis=0)
    feature = np.abs(regressors).max(axis=0)
    force = np.array([NEGLIGIBLE_FORCE[model.input_names[r]] for r in rows])
    cruise = np.array([abs(getattr(model.params, n)) for n in names])
    return np.maximum(cruise, force / feature)


def make_filter(model: ROVModel, batch: int, theta0: FloatArray,
                x0: FloatArray) -> ExtendedKalmanFilter:
    """The joint state-and-coefficient EKF of ``batch`` robots.

    :param theta0: initial coefficient guesses ``(batch, 18)``.
    :param x0: initial state (13,), known to the robot to the sensors' accuracy.
    """
    scales = coefficient_scales(model)
    noise = DEFAULT_SENSORS["noise_std"]
    R = np.array([noise[c] for c in CHANNELS]) ** 2
    inertia = np.diag(model.mass_matrix(0.0))
    Q = np.zeros(13)
    Q[:6] = (FORCE_NOISE / inertia * DT) ** 2  # force error held over a period
    Q[12] = 1e-12  # the shape follows the known command exactly
    state_std = np.array([0.02] * 3 + [0.01] * 3 + [1.0, 1.0, 0.05] + [0.01] * 3 + [1e-6])
    P0 = np.diag(np.concatenate([state_std, PRIOR_FRACTION * scales]) ** 2)
    ekf = ExtendedKalmanFilter.from_model(
        model, DT, measured=CHANNELS, Q=Q, R=R, parameters=SEED_COEFFICIENTS,
        parameter_noise=RATE * scales, P0=P0, angular=("psi",), substeps=2, batch_size=batch)
    ekf.reset(np.column_stack([np.tile(x0, (batch, 1)), theta0]))
    return ekf


def fly(seeds: int = 2, morph_time: float = 40.0, duration: float = 110.0,
        excitation: Excitation | None = None, seed: int = 0,
        bar: tqdm | None = None) -> dict[str, Any]:
    """Fly ``seeds`` robots with the identified feed-forward and ``seeds`` with the nominal one.

    :return: ``time`` (T,), ``estimate`` and ``std`` (T, 2 seeds, 18), ``truth`` (T, 18) at the
        hull's shape, ``error`` (T, 2 seeds, 6) of :data:`ERROR_CHANNELS`, ``theta0``,
        ``prior_std``, ``diverged``; rows ``[:seeds]`` fly the identified feed-forward.
    """
    excitation = Excitation() if excitation is None else excitation
    model = ROVModel()
    batch, steps = 2 * seeds, int(round(duration / DT))
    env = gym.make_vec(ENV_ID, num_envs=batch, vectorization_mode="vector_entry_point",
                       max_episode_steps=None, current=(0.0, 0.0, 0.0), current_std=0.0,
                       morph_time=morph_time)
    cruise = np.array([getattr(model.params, n) for n in SEED_COEFFICIENTS])
    prior_std = PRIOR_FRACTION * coefficient_scales(model)
    guess = cruise + prior_std * np.random.default_rng(seed).standard_normal((seeds, cruise.size))
    x0, _ = excitation(0.0)
    ekf = make_filter(model, batch, np.concatenate([guess, guess]), x0)
    tracker = FeedforwardTracker(model, DT, integral={"u": 4.0, "z": 1.0, "psi": 10.0})
    actuation = env.unwrapped.system.actuation
    obs, info = env.reset(seed=seed, options={"state": x0})
    ekf.update(obs.astype(float), info["measurement_mask"])
    out = {"estimate": np.empty((steps, batch, cruise.size)), "std": np.empty((steps, batch,
           cruise.size)), "truth": np.empty((steps, cruise.size)),
           "error": np.empty((steps, batch, len(ERROR_CHANNELS)))}
    for k in range(steps):
        x_ref, nu_dot = excitation(k * DT)
        x_ref = np.tile(x_ref, (batch, 1))
        x_ref[:, 12] = ekf.x[:, 12]  # the known shape
        theta = ekf.parameters.copy()
        theta[seeds:] = cruise
        tau = tracker(ekf.x[:, :13], x_ref, np.tile(nu_dot, (batch, 1)), theta)
        obs, _, terminated, _, info = env.step(actuation.to_action(tau))
        if terminated.any():
            raise RuntimeError(f"robot(s) {np.flatnonzero(terminated).tolist()} left the "
                               f"envelope at t = {(k + 1) * DT:.1f} s")
        ekf.disturbance = info["disturbance"].copy()  # the morph command, known
        ekf.predict(info["action_applied"])
        ekf.update(obs.astype(float), info["measurement_mask"])
        _record(out, k, ekf, info["state"], excitation((k + 1) * DT)[0], model)
        if bar is not None and k % 100 == 99:
            bar.update(100)
    env.close()
    out.update(time=np.arange(1, steps + 1) * DT, theta0=guess, prior_std=prior_std,
               diverged=ekf.diverged.copy(), seeds=seeds, morph_time=morph_time)
    return out


def _record(out: dict[str, Any], k: int, ekf: ExtendedKalmanFilter, state: FloatArray,
            x_ref: FloatArray, model: ROVModel) -> None:
    out["estimate"][k], out["std"][k] = ekf.parameters, ekf.parameter_std
    shape = model.coefficients(float(state[0, 12]))  # every robot morphs at the same time
    out["truth"][k] = [shape[n] for n in SEED_COEFFICIENTS]
    error = state[:, _ERROR_INDEX] - x_ref[_ERROR_INDEX]
    error[:, -1] = (error[:, -1] + math.pi) % (2 * math.pi) - math.pi
    out["error"][k] = error


# -- analysis -------------------------------------------------------------------------------------
def tracking_time(run: dict[str, Any], name: str, tolerance: float = TOLERANCE) -> list[float]:
    """Per identified robot: time after the morph (s) from which the estimate of ``name`` stays
    within ``tolerance`` of its work-shape value until the end; NaN if it is outside at the end."""
    j = SEED_COEFFICIENTS.index(name)
    after = run["time"] > run["morph_time"]
    est = run["estimate"][after][:, :run["seeds"], j]
    return [_settling_time(column, run["time"][after] - run["morph_time"], _work_values()[j],
                           tolerance) for column in est.T]


def physical_tracking_time(run: dict[str, Any], name: str,
                           tolerance: float = TOLERANCE) -> float:
    """The same for the true coefficient itself (the hull's own lag, T_m = 5 s): the lower
    bound of :func:`tracking_time`."""
    j = SEED_COEFFICIENTS.index(name)
    after = run["time"] > run["morph_time"]
    return _settling_time(run["truth"][after, j], run["time"][after] - run["morph_time"],
                          _work_values()[j], tolerance)


def _settling_time(values: FloatArray, times: FloatArray, target: float,
                   tolerance: float) -> float:
    """First of ``times`` from which ``values`` stay within ``tolerance`` of ``target``."""
    outside = np.flatnonzero(np.abs(values - target) > tolerance * abs(target))
    if outside.size == 0:
        return 0.0
    return math.nan if outside[-1] == values.size - 1 else float(times[outside[-1] + 1])


def rms_error(run: dict[str, Any], rows: slice, start: float, stop: float) -> FloatArray:
    """Per robot: RMS over ``start < t <= stop`` of the Bryson-normalised tracking error (the
    root of the mean of ``sum_c (e_c / scale_c)^2``), dimensionless."""
    window = (run["time"] > start) & (run["time"] <= stop)
    e = run["error"][window][:, rows] / _ERROR_SCALE
    return np.sqrt((e ** 2).sum(axis=2).mean(axis=0))


def channel_rms(run: dict[str, Any], rows: slice, start: float) -> dict[str, float]:
    """RMS error of each channel after ``start`` (s), in its unit (deg for angles), mean over
    robots."""
    e = run["error"][run["time"] > start][:, rows]
    rms = np.sqrt((e ** 2).mean(axis=0)).mean(axis=0)
    return {c + ("_deg" if c in ("theta", "psi") else ""): float(v / DEG if c in ("theta", "psi")
                                                                  else v)
            for c, v in zip(ERROR_CHANNELS, rms, strict=True)}


def identifiability(run: dict[str, Any]) -> FloatArray:
    """Per coefficient: final posterior std over the std it would have without any data
    (prior plus the random walk's growth), mean over the identified robots; about 1 = the
    manoeuvre taught the filter nothing."""
    duration = run["time"][-1]
    no_data = np.sqrt(run["prior_std"] ** 2 + (RATE * run["prior_std"] / PRIOR_FRACTION) ** 2
                      * duration)
    return run["std"][-1, :run["seeds"]].mean(axis=0) / no_data


def classify(ratio: float) -> str:
    """``identified`` (the data removed most of the uncertainty), ``weak`` or ``unidentified``."""
    return "identified" if ratio < 0.35 else "weak" if ratio < 0.75 else "unidentified"


def _work_values() -> FloatArray:
    work = ROVModel().coefficients(1.0)
    return np.array([work[n] for n in SEED_COEFFICIENTS])


def _window_mean(run: dict[str, Any], key: str, start: float, stop: float) -> FloatArray:
    """Per identified robot and coefficient: mean of ``run[key]`` over ``start < t <= stop``."""
    window = (run["time"] > start) & (run["time"] <= stop)
    return run[key][window][:, :run["seeds"]].mean(axis=0)


def summarise(run: dict[str, Any], window: float = 10.0) -> dict[str, Any]:
    """The JSON summary of a :func:`fly` run (see the module docstring)."""
    seeds, morph, end = run["seeds"], run["morph_time"], float(run["time"][-1])
    model = ROVModel()
    before, after = model.coefficients(0.0), model.coefficients(1.0)
    est_b = _window_mean(run, "estimate", morph - window, morph)
    est_a = _window_mean(run, "estimate", end - window, end)
    std_b = _window_mean(run, "std", morph - window, morph)
    std_a = _window_mean(run, "std", end - window, end)
    ratio = identifiability(run)
    coefficients = {}
    for j, name in enumerate(SEED_COEFFICIENTS):
        times = tracking_time(run, name)
        coefficients[name] = {
            "true_before": before[name], "true_after": after[name],
            "estimate_before": float(est_b[:, j].mean()),
            "estimate_after": float(est_a[:, j].mean()),
            "std_before": float(std_b[:, j].mean()), "std_after": float(std_a[:, j].mean()),
            "estimate_before_spread": spread(est_b[:, j]),
            "estimate_after_spread": spread(est_a[:, j]),
            "initial_guess": spread(run["theta0"][:, j]), "prior_std": float(run["prior_std"][j]),
            "changes_with_morph": name in MORPHING, "information_ratio": float(ratio[j]),
            "identifiability": classify(float(ratio[j])),
            "tracking_time_s": _mean_or_none(times),
            "physical_tracking_time_s": physical_tracking_time(run, name)}
    per_seed = np.max([tracking_time(run, n) for n in TRACKED], axis=0)
    ff, nominal = slice(0, seeds), slice(seeds, 2 * seeds)
    return {
        "coefficients": coefficients, "morph_time": morph,
        "tracking_time_s": _mean_or_none(per_seed),
        "tracking_time_s_spread": spread(np.nan_to_num(per_seed, nan=end - morph)),
        "physical_tracking_time_s": max(physical_tracking_time(run, n) for n in TRACKED),
        "tracked": list(TRACKED), "tolerance": TOLERANCE,
        "feedforward": _control_summary(run, ff), "nominal": _control_summary(run, nominal),
        "error_reduction": 1 - float(rms_error(run, ff, morph, end).mean()
                                     / rms_error(run, nominal, morph, end).mean()),
        "identified": [n for n, c in coefficients.items() if c["identifiability"] == "identified"],
        "weak": [n for n, c in coefficients.items() if c["identifiability"] == "weak"],
        "unidentified": [n for n, c in coefficients.items()
                         if c["identifiability"] == "unidentified"],
        "diverged": int(run["diverged"].sum()), "conditions": _conditions(run)}


def _mean_or_none(values: Any) -> float | None:
    """Mean of per-seed values, or None (JSON null) when any is NaN (not tracked)."""
    v = np.asarray(values, dtype=float)
    return None if np.isnan(v).any() else float(v.mean())


def _control_summary(run: dict[str, Any], rows: slice) -> dict[str, Any]:
    morph, end = run["morph_time"], float(run["time"][-1])
    after = rms_error(run, rows, morph, end)
    before = rms_error(run, rows, min(20.0, morph / 2), morph)
    return {"rms_tracking_error": float(after.mean()), "rms_tracking_error_spread": spread(after),
            "rms_tracking_error_before": float(before.mean()),
            "rms_by_channel_after": channel_rms(run, rows, morph)}


def _conditions(run: dict[str, Any]) -> dict[str, Any]:
    return {
        "seeds": run["seeds"], "duration_s": float(run["time"][-1]), "dt_s": DT,
        "plant": "ROV-v0 (Prestero REMUS-100, docs/models.md 3), force actuation without "
                 "roll moment, still water, DVL 5 Hz + gyro + depth 10 Hz (ROV-v0 noise)",
        "excitation": dataclasses.asdict(Excitation()),
        "parameter_noise": f"q_i = {RATE} * scale_i per sqrt(s), scale_i = max(|c_i|, value "
                           "giving 0.5 N or N m (roll 0.05 N m) at 1.5 m/s, 0.2 m/s, 0.2 rad/s)",
        "prior": f"cruise values + N(0, ({PRIOR_FRACTION} scale)^2), drawn per seed",
        "controller": "discrete LQR of the cruise linearisation with integral action on u, z, "
                      "psi, on the EKF state, plus inverse-dynamics feed-forward of the "
                      "reference; feedforward: identified coefficients, nominal: cruise values",
        "tracking_error": "RMS over t > morph_time of sqrt(sum_c (e_c / s_c)^2), c in "
                          f"{list(ERROR_CHANNELS)}, s_c = {_ERROR_SCALE.round(4).tolist()} "
                          "(m/s, m, rad)",
        "information_ratio": "final posterior std / std without data (prior + random walk); "
                             "identified < 0.35 <= weak < 0.75 <= unidentified"}


# -- the command ----------------------------------------------------------------------------------
def reproduce(quick: bool = False, progress: bool = True) -> Reproduction:
    """Full: 5 seeds, morph at 60 s, 240 s; quick: 2 seeds, morph at 40 s, 110 s."""
    seeds, morph, duration = (2, 40.0, 110.0) if quick else (5, 60.0, 240.0)
    with tqdm(total=int(duration / DT), desc="rov-online-id", unit="step",
              disable=not progress, mininterval=1.0) as bar:
        run = fly(seeds, morph, duration, bar=bar)
    summary = summarise(run)
    return Reproduction("rov-online-id", summary, _text(summary),
                        lambda path: _plot(run, path))


def _text(summary: dict[str, Any]) -> str:
    c = summary["conditions"]
    lines = [f"The morphing-robot patent: online identification of 18 viscous coefficients "
             f"({c['seeds']} seeds x {c['duration_s']:.0f} s, morph at "
             f"{summary['morph_time']:.0f} s; estimates are means over seeds)", "",
             f"{'coef':5} {'true before':>12} {'estimate':>10} {'std':>8} {'true after':>11} "
             f"{'estimate':>10} {'std':>8} {'info':>5}  verdict"]
    for name, r in summary["coefficients"].items():
        lines.append(f"{name:5} {r['true_before']:12.4g} {r['estimate_before']:10.4g} "
                     f"{r['std_before']:8.3g} {r['true_after']:11.4g} {r['estimate_after']:10.4g} "
                     f"{r['std_after']:8.3g} {r['information_ratio']:5.2f}  "
                     f"{r['identifiability']}")
    tt = summary["tracking_time_s"]
    spread_ = summary["tracking_time_s_spread"]
    lines += ["", f"time after the morph until {' and '.join(summary['tracked'])} stay within "
              f"{summary['tolerance']:.0%} of the work-shape values: "
              + ("not reached" if tt is None else f"{tt:.1f} s (max {spread_['max']:.1f} s; "
                 f"the hull itself takes {summary['physical_tracking_time_s']:.1f} s)"),
              "RMS normalised tracking error after the morph:"]
    for label in ("feedforward", "nominal"):
        r = summary[label]
        s = r["rms_tracking_error_spread"]
        lines.append(f"  {label:12} {s['mean']:.3f} +- {s['std']:.3f}   (before the morph "
                     f"{r['rms_tracking_error_before']:.3f}; u "
                     f"{r['rms_by_channel_after']['u']:.4f} m/s)")
    lines += [f"  reduction by the identified feed-forward: {summary['error_reduction']:.0%}",
              "", f"unidentified with this manoeuvre: {', '.join(summary['unidentified'])}; "
              f"weak: {', '.join(summary['weak'])}", f"controller: {c['controller']}",
              f"parameter noise: {c['parameter_noise']}"]
    return "\n".join(lines)


def _plot(run: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, seeds, morph = run["time"], run["seeds"], run["morph_time"]
    fig = plt.figure(figsize=(15, 17))
    grid = fig.add_gridspec(7, 3)
    for j, name in enumerate(SEED_COEFFICIENTS):
        ax = fig.add_subplot(grid[j // 3, j % 3])
        est, std = run["estimate"][:, 0, j], run["std"][:, 0, j]
        ax.fill_between(t, est - 2 * std, est + 2 * std, alpha=0.25, lw=0)
        for i in range(seeds):
            ax.plot(t, run["estimate"][:, i, j], lw=0.8, color=f"C{i}", alpha=0.9)
        ax.plot(t, run["truth"][:, j], "k--", lw=1.2, label="true")
        ax.axvline(morph, color="grey", lw=0.8)
        low, high = np.percentile(run["truth"][:, j], [0, 100])
        pad = max(high - low, 0.3 * max(abs(low), abs(high)), 1e-3)
        ax.set_ylim(low - pad, high + pad)
        ax.set_title(name, fontsize=10)
        ax.grid(alpha=0.3)
    _plot_errors(fig, grid, run)
    fig.suptitle("The morphing-robot patent: coefficient estimates (one line per seed, +-2 std "
                 "band of seed 0) vs the true values; morph at the grey line", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 0.98))
    save_figure(fig, path, dpi=90)
    plt.close(fig)


def _plot_errors(fig: Any, grid: Any, run: dict[str, Any]) -> None:
    t, seeds = run["time"], run["seeds"]
    panels = (("u", 1.0, "surge speed error (m/s)"), ("psi", 1 / DEG, "heading error (deg)"),
              (None, 1.0, "normalised tracking error"))
    for col, (channel, factor, label) in enumerate(panels):
        ax = fig.add_subplot(grid[6, col])
        for rows, name in ((slice(seeds, 2 * seeds), "nominal"), (slice(0, seeds),
                                                                  "feed-forward")):
            e = run["error"][:, rows] / _ERROR_SCALE
            y = np.sqrt((e ** 2).sum(axis=2)) if channel is None else \
                run["error"][:, rows, ERROR_CHANNELS.index(channel)] * factor
            ax.plot(t, y[:, 0], lw=0.7, label=name)
        ax.axvline(run["morph_time"], color="grey", lw=0.8)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
