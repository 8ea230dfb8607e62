"""EPFL hovercraft runs: the frame check, the parameter fit, the comparison with the model and
the conversion into ``hovercraft_epfl_<run>.csv`` and ``hovercraft_epfl_params.json`` (the
runs are loaded by ``hovercraft_epfl_load``).

Frame and thruster mapping of the hovercraft (established from the data, printed when run):
the source's converter writes pose x = OptiTrack z, pose y = OptiTrack x and pose yaw = the
rotation about OptiTrack's vertical y axis (Y-up). The craft accelerates along the direction
(cos yaw, sin yaw) of the (pose x, pose y) plane, so yaw is measured from pose x towards pose y,
which is counter-clockwise seen from above. The NED-like frame of the model (psi clockwise from
above) is therefore north = pose x, east = -pose y, psi = -yaw. In that frame the command the
source labels "left thrust" (field.point.x) yaws the craft to port (r < 0), which is what a
starboard thruster does, so sigma_2 (starboard) = field.point.x and sigma_1 (port) =
field.point.y. Should OptiTrack have streamed a Y-down frame, both the frame and the labels
mirror and the source's labels would be right; the recording is self-consistent either way.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.integrate import solve_ivp

from .common import DECIMATION, FS_IN, FS_OUT, _write
from .hovercraft_epfl_load import HOVER_DIR, HoverRun, load_hover_run

HOVER_RUNS = ("2019-04-16-11-24-59", "2019-04-16-11-28-36")
HOVER_CHECK_RUNS = ("2019-04-16-11-30-28", "2019-04-16-11-32-20", "2019-04-16-12-29-28")
HOVER_PARAMS_OUT = "hovercraft_epfl_params.json"
# Source values of the TinyWhoover hovercraft (hovercraft-ros, src/ground/src/controller.py:
# "coefficients estimated in system identification"); m and the lever arm are kept, the rest is
# refitted here.
SOURCE_PARAMS = {"m": 0.0583, "Iz": 89e-6, "d_v": 33e-3, "d_r": 31e-6, "k": 80e-3,
                 "l": 0.0325}
U_T = 15.0  #: speed at which the thrust vanishes, m/s [rough estimate for ~30 mm props]
ATTRIBUTION_HOVER = (
    "EPFL indoor hovercraft (TinyWhoover), system-identification run {run} with an on/off "
    "pseudo-random binary thrust sequence and OptiTrack motion capture; from the repository "
    "MauroPfister/hovercraft-ros at commit 73bd403, data_id/controls_{run}.csv and "
    "data_id/pose_{run}.csv. (c) 2019 Mauro Pfister, MIT licence (LICENSE-hovercraft-epfl).")


def body_motion(fine: dict[str, np.ndarray], cutoff: float | None = None
                ) -> dict[str, np.ndarray]:
    """Body velocities and the body-frame components of the acceleration from the 100 Hz pose.

    ``a_x = u_dot - v r`` and ``a_y = v_dot + u r`` are what the model's rigid-body equations
    equate to force over mass (no added mass). ``cutoff`` (Hz): an extra zero-phase low-pass of
    the pose before differencing (apply the same one to the regressors of a fit).
    """
    dt = 1.0 / FS_IN
    sig = {k: (_lowpass(fine[k], cutoff) if cutoff else fine[k]) for k in ("north", "east", "psi")}
    d = {k: np.gradient(v, dt) for k, v in sig.items()}
    dd = {k: np.gradient(v, dt) for k, v in d.items()}
    c, s = np.cos(sig["psi"]), np.sin(sig["psi"])
    return {"u": c * d["north"] + s * d["east"], "v": -s * d["north"] + c * d["east"],
            "r": d["psi"], "a_x": c * dd["north"] + s * dd["east"],
            "a_y": -s * dd["north"] + c * dd["east"], "r_dot": dd["psi"],
            "v_north": d["north"], "v_east": d["east"], "a_north": dd["north"],
            "a_east": dd["east"], "psi": sig["psi"]}


def _lowpass(x: np.ndarray, cutoff: float) -> np.ndarray:
    """Zero-phase FIR low-pass at ``cutoff`` Hz of a 100 Hz signal."""
    return signal.filtfilt(signal.firwin(101, cutoff, fs=FS_IN), 1.0, x, padtype="odd")


def _held(run: HoverRun, lag: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The commands (zero-order hold) at the 100 Hz times, acting ``lag`` s late."""
    k = np.clip(np.floor((run.fine["time"] - lag) * FS_OUT + 1e-9).astype(int), 0,
                len(run.time) - 1)
    return run.sigma_1[k], run.sigma_2[k]


FIT_CUTOFF = 2.0  #: low-pass (Hz) applied alike to the pose and the regressors of the fit
INNER = slice(100, -100)  #: samples of the 100 Hz signals used in fits (1 s of filter edge off)


def check_hover_frame(runs: list[HoverRun]) -> None:
    """Print the two checks behind the frame and the thruster mapping."""
    for run in runs:
        b = body_motion(run.fine, FIT_CUTOFF)
        s1, s2 = _held(run, 0.05)
        # force direction (acceleration plus a linear-drag guess v / 2 s) against the heading
        both = (s1 + s2 == 2)[INNER]
        force = np.arctan2(b["a_east"] + b["v_east"] / 2, b["a_north"] + b["v_north"] / 2)
        z = np.exp(1j * (force - b["psi"]))[INNER][both].mean()
        A = np.c_[(s1 - s2), (s1 + s2), np.ones_like(s1)]
        A = np.c_[np.apply_along_axis(_lowpass, 0, A, FIT_CUTOFF), b["r"]][INNER]
        coef = np.linalg.lstsq(A, b["r_dot"][INNER], rcond=None)[0]
        print(f"  {run.run}: with both thrusters on the craft accelerates at "
              f"{math.degrees(np.angle(z)):+.1f} deg from the heading (resultant {abs(z):.2f}); "
              f"r_dot = {coef[0]:+.1f} (sigma_1 - sigma_2) {coef[1]:+.1f} (sigma_1 + sigma_2) "
              f"{coef[2]:+.2f} {coef[3]:+.2f} r [rad/s^2]")


def fit_hover_params(runs: list[HoverRun], lag: float = 0.05) -> tuple[dict[str, float],
                                                                        dict[str, float]]:
    """Lab-scale overrides of the LCAC model by equation error (linear least squares).

    With no added mass, thrust ``T0 sigma (1 - u/U_T)`` and linear drag the model's equations
    are, with ``a_x = u_dot - v r`` and ``a_y = v_dot + u r`` (the body components of the
    acceleration)::

        m a_x    = T0 (s1 + s2)(1 - u/U_T) + X_Hu u
        m a_y    = Y_Hv v
        Iz r_dot = y_P T0 (s1 - s2)(1 - u/U_T) + N_Hr r

    m and y_P are the source's; T0, X_Hu, Y_Hv, Iz and N_Hr follow from the per-mass fits. Pose
    and regressors are low-passed alike (``FIT_CUTOFF``) so that the filter does not bias the
    fit. The commands act ``lag`` s late (motor response). The yaw fit also estimates a constant
    yaw acceleration (not in the model) so that this bias does not leak into the other
    coefficients; it is reported as missing physics.
    """
    eqs: dict[str, tuple[list[np.ndarray], list[np.ndarray]]] = {
        k: ([], []) for k in ("surge", "sway", "yaw")}
    for run in runs:
        b = body_motion(run.fine, FIT_CUTOFF)
        s1, s2 = _held(run, lag)
        raw = body_motion(run.fine)
        factor = 1 - raw["u"] / U_T

        def lp(*cols: np.ndarray) -> np.ndarray:
            return np.c_[tuple(_lowpass(c, FIT_CUTOFF) for c in cols)][INNER]

        eqs["surge"][0].append(lp((s1 + s2) * factor, raw["u"]))
        eqs["surge"][1].append(b["a_x"][INNER])
        eqs["sway"][0].append(lp(raw["v"]))
        eqs["sway"][1].append(b["a_y"][INNER])
        eqs["yaw"][0].append(lp((s1 - s2) * factor, raw["r"], np.ones_like(s1)))
        eqs["yaw"][1].append(b["r_dot"][INNER])
    coef = {}
    for key, (rows, rhs) in eqs.items():
        A, y = np.concatenate(rows), np.concatenate(rhs)
        c = np.linalg.lstsq(A, y, rcond=None)[0]
        coef[key] = (c, 1 - np.var(y - A @ c) / np.var(y))
    m, y_p = SOURCE_PARAMS["m"], SOURCE_PARAMS["l"]
    (a_t, a_u), r2_u = coef["surge"]
    (b_v,), r2_v = coef["sway"]
    (c_t, c_r, c_0), r2_r = coef["yaw"]
    t0 = a_t * m
    iz = y_p * t0 / c_t
    fitted = {"T0": t0, "X_Hu": a_u * m, "Y_Hv": b_v * m, "Iz": iz, "N_Hr": c_r * iz}
    info = {"r2_surge": r2_u, "r2_sway": r2_v, "r2_yaw": r2_r, "yaw_bias_rad_s2": c_0,
            "yaw_bias_moment_Nm": c_0 * iz, "lag_s": lag}
    return fitted, info


def hover_params(fitted: dict[str, float], u_cruise: float) -> dict[str, float]:
    """The complete override set: the fitted values, the source's m and y_P, no added mass, no
    aerodynamic or nonlinear hull terms, no rudder (the lab craft has none)."""
    from marine_envs.models.hovercraft import HovercraftParams

    zero = [f for f in HovercraftParams.__dataclass_fields__
            if f[:3] in ("X_A", "Y_A", "N_A", "X_H", "Y_H", "N_H") or f.startswith("C_R")]
    params = dict.fromkeys(zero, 0.0)
    params.update({
        "m": SOURCE_PARAMS["m"], "X_ud": 0.0, "Y_vd": 0.0, "N_rd": 0.0, "N_vd": 0.0,
        "y_P": SOURCE_PARAMS["l"], "U_T": U_T, "D_p": 0.031, "L": 0.10, "B": 0.09,
        "S_R": 1e-4, "x_R": -0.05, "k_s": 0.0, "u_cruise": u_cruise,
    })
    params.update(fitted)
    return {k: float(f"{v:.4g}") for k, v in params.items()}


def simulate(model, run: HoverRun, x0: np.ndarray) -> np.ndarray:
    """Open-loop simulation on the recorded inputs (held between samples), states at run.time."""
    u = np.c_[run.sigma_1, run.sigma_2, np.zeros(len(run.time))]
    xs = [x0]
    x = x0
    for k in range(len(run.time) - 1):
        sol = solve_ivp(lambda _t, s, uk=u[k]: model.rhs(s, uk), (0.0, 1 / FS_OUT), x,
                        rtol=1e-6, atol=1e-9)
        x = sol.y[:, -1]
        xs.append(x)
    return np.array(xs)


def compare_hover(model, runs: list[HoverRun], label: str) -> dict[str, dict[str, float]]:
    """Peak and mean speed and yaw rate, recorded vs simulated (open loop, whole run), and the
    median error of 1 s ahead predictions from the recorded state."""
    out = {}
    for run in runs:
        b = body_motion(run.fine)
        at = np.arange(0, len(run.fine["time"]), DECIMATION)
        x_rec = np.c_[b["u"][at], b["v"][at], b["r"][at], run.north, run.east, run.psi]
        sim = simulate(model, run, x_rec[0])
        speed_rec, speed_sim = np.hypot(x_rec[:, 0], x_rec[:, 1]), np.hypot(sim[:, 0], sim[:, 1])
        # 1 s ahead predictions from every recorded state
        err_r, err_speed = [], []
        for k in range(0, len(run.time) - 10, 5):
            sub = HoverRun(run.run, run.time[k:k + 11] - run.time[k], run.sigma_1[k:k + 11],
                           run.sigma_2[k:k + 11], run.north[k:k + 11], run.east[k:k + 11],
                           run.psi[k:k + 11], 0.0, [], 0, {})
            pred = simulate(model, sub, x_rec[k])[-1]
            err_r.append(abs(pred[2] - x_rec[k + 10, 2]))
            err_speed.append(abs(np.hypot(pred[0], pred[1]) - speed_rec[k + 10]))
        stats = {"peak_speed_rec": speed_rec.max(), "peak_speed_sim": speed_sim.max(),
                 "mean_speed_rec": speed_rec.mean(), "mean_speed_sim": speed_sim.mean(),
                 "peak_abs_r_rec": np.abs(x_rec[:, 2]).max(),
                 "peak_abs_r_sim": np.abs(sim[:, 2]).max(),
                 "mean_r_rec": x_rec[:, 2].mean(), "mean_r_sim": sim[:, 2].mean(),
                 "median_err_r_1s": float(np.median(err_r)),
                 "median_err_speed_1s": float(np.median(err_speed))}
        out[run.run] = {k: round(float(v), 3) for k, v in stats.items()}
        print(f"  {label:>7} {run.run}: speed peak {stats['peak_speed_rec']:.2f} rec / "
              f"{stats['peak_speed_sim']:.2f} sim, mean {stats['mean_speed_rec']:.2f} / "
              f"{stats['mean_speed_sim']:.2f} m/s; |r| peak {stats['peak_abs_r_rec']:.1f} / "
              f"{stats['peak_abs_r_sim']:.1f}, mean r {stats['mean_r_rec']:+.2f} / "
              f"{stats['mean_r_sim']:+.2f} rad/s; 1 s ahead median error r "
              f"{stats['median_err_r_1s']:.2f} rad/s, speed {stats['median_err_speed_1s']:.2f} m/s")
    return out


def convert_hovercraft(source: Path, out: Path, dry_run: bool) -> None:
    from marine_envs.models import get_model
    from marine_envs.recording import Recording

    print("== EPFL hovercraft")
    runs = [load_hover_run(source, run) for run in HOVER_RUNS]
    for run in runs:
        print(f"  {run.run}: {len(run.time)} samples ({run.time[-1]:.1f} s), lift fan on "
              f"throughout, {run.glitches} glitch frames dropped, {len(run.gaps)} pose gaps > "
              f"50 ms bridged (longest {max(b - a for a, b in run.gaps):.2f} s)")
    print("  frame check (north = pose x, east = -pose y, psi = -yaw; sigma_1 = field.point.y, "
          "sigma_2 = field.point.x):")
    check_hover_frame(runs)
    fitted, info = fit_hover_params(runs)
    speed = np.concatenate([np.hypot(body_motion(r.fine)["u"], body_motion(r.fine)["v"])
                            for r in runs])
    params = hover_params(fitted, u_cruise=round(float(np.median(speed)), 2))
    print(f"  fit (R^2 surge {info['r2_surge']:.2f}, sway {info['r2_sway']:.2f}, yaw "
          f"{info['r2_yaw']:.2f}): " + ", ".join(f"{k} = {params[k]:.4g}" for k in fitted))
    print(f"  source (hovercraft-ros controller.py): T0 = k = {SOURCE_PARAMS['k']}, X_Hu = Y_Hv "
          f"= -d_v = {-SOURCE_PARAMS['d_v']}, Iz = {SOURCE_PARAMS['Iz']}, N_Hr = -d_r = "
          f"{-SOURCE_PARAMS['d_r']}")
    print(f"  not in the model: constant yaw acceleration {info['yaw_bias_rad_s2']:+.2f} rad/s^2 "
          f"(moment {info['yaw_bias_moment_Nm']:+.2e} N m)")
    model = get_model("hovercraft", **params)
    source_like = dict(params, T0=SOURCE_PARAMS["k"], X_Hu=-SOURCE_PARAMS["d_v"],
                       Y_Hv=-SOURCE_PARAMS["d_v"], Iz=SOURCE_PARAMS["Iz"],
                       N_Hr=-SOURCE_PARAMS["d_r"])
    checks = {"fitted": compare_hover(model, runs, "fitted")}
    checks["source"] = compare_hover(get_model("hovercraft", **source_like), runs, "source")
    checks["LCAC"] = compare_hover(get_model("hovercraft"), runs, "LCAC")

    for run in runs:
        meta = {
            "source": ATTRIBUTION_HOVER.format(run=run.run),
            "licence": "MIT",
            "description": (
                "A ~60 g indoor hovercraft driven by a pseudo-random on/off sequence of its two "
                "thrusters with the lift fan on, tracked by motion capture. Inputs sigma_1 "
                "(port) and sigma_2 (starboard) are the 0/1 thrust commands; there is no rudder "
                "(delta = 0). Only north, east and psi are measured. Known to contain: very "
                "low lateral friction (large sideslip), a constant yaw moment that spins the "
                "craft (lift-fan reaction or motor asymmetry), a thrust direction a few degrees "
                "off the heading, and a motor response delay of about 50 ms."),
            "sample_rate_hz": FS_OUT,
            "run": run.run,
            "processing": {
                "time_base": ("the thrust commands' header stamps: sample k at the k-th "
                              "command after the first with the lift fan on and the pose "
                              "tracked; command k held until sample k+1"),
                "t0_ros_time_s": round(run.t0_stamp, 6),
                "frame": ("north = pose field.point.x, east = -pose field.point.y, psi = "
                          "-unwrapped field.point.z: right-handed with z down if OptiTrack is "
                          "Y-up (the source's converter.py writes pose x = OptiTrack z, pose y "
                          "= OptiTrack x, yaw about OptiTrack y); origin and axes are the "
                          "motion-capture room's"),
                "inputs": ("sigma_1 = field.point.y (labelled 'right thrust' in the source), "
                           "sigma_2 = field.point.x (labelled 'left thrust'): in this frame "
                           "field.point.x yaws the craft to port, as a starboard thruster "
                           "does; sigma = command (0 = off, 1 = on; the model's thrust is "
                           "T0 sigma), delta = 0"),
                "pose": ("bursts of frames with one VRPN stamp spread over the 10 ms poll "
                         "before it; single-frame glitches (mirrored yaw, position jumps) "
                         "dropped; yaw unwrapped with the recent yaw rate across gaps; linear "
                         "interpolation on a 100 Hz grid phased on the commands, then "
                         "scipy.signal.resample_poly(x, 1, 10, padtype='line') "
                         "(zero-phase anti-alias FIR)"),
                "glitch_frames_dropped": run.glitches,
                "pose_gaps_bridged_s": run.gaps,
            },
            "params_fit": {k: float(f"{v:.4g}") for k, v in info.items()},
            "model_check": checks["fitted"][run.run],
            "model_check_note": ("the model with these params simulated open loop over the "
                                 "whole run from the recorded initial state (rec = recording, "
                                 "sim = simulation; speed in m/s, r in rad/s, derived from the "
                                 "100 Hz pose), and the median error of 1 s ahead predictions "
                                 "from recorded states"),
            "params_note": ("params: lab-scale overrides of the LCAC model (see "
                            "hovercraft_epfl_params.json and README.md); m and y_P from the "
                            "source, T0, Iz, X_Hu, Y_Hv, N_Hr fitted by equation error"),
        }
        rec = Recording.from_arrays(
            "hovercraft", run.time, np.c_[run.sigma_1, run.sigma_2, np.zeros(len(run.time))],
            {"north": np.round(run.north, 6), "east": np.round(run.east, 6),
             "psi": np.round(run.psi, 6)}, params=params, meta=meta)
        _write(rec, out / f"hovercraft_epfl_{run.run}.csv", dry_run)
    print("  out of sample (runs not shipped; 11-35-57 is left out, its tracking is corrupt "
          "from 10 to 15 s):")
    compare_hover(model, [load_hover_run(source, run) for run in HOVER_CHECK_RUNS], "fitted")
    if not dry_run:
        (out / HOVER_PARAMS_OUT).write_text(json.dumps(params, indent=2) + "\n",
                                            encoding="utf-8")
        print(f"  wrote {out / HOVER_PARAMS_OUT}")
        shutil.copyfile(source / HOVER_DIR / "LICENSE", out / "LICENSE-hovercraft-epfl")
