"""A diagnosis as a human-readable report: ``report.md``, its PNG figures and ``diagnosis.json``.

:func:`write_report` writes, into one directory,

* ``diagnosis.json``: :meth:`Diagnosis.to_dict` (the documented JSON);
* ``prediction_errors.png``: per measured channel, the held-out multi-step prediction error at the
  end of the horizon against its start time, before and after the findings, located windows
  shaded;
* ``spectra.png``: Welch spectra of the equation errors of the measured states before and after
  subtracting the findings' contributions, the located band shaded;
* ``finding_<k>_<effect>_<target>.png``: each finding's fitted term against the data it explains;
* ``report.md``: verdict, location, findings, held-out fit, the figures and how to read them.

A recording the tool cannot judge (``mismatch is None``) gets the verdict and the reason only.
Units are the model's SI units (angles in rad); frequencies are in rad/s like ``band``.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal

from marine_envs.files import WriteError, write_text
from marine_envs.models.effects import Effect, applied_inputs, state_term

from . import free_simulation_figures, free_simulation_report
from .report_format import cell, change, num, parameters, pyplot, save, slug
from .residuals import Residuals
from .result import Diagnosis, Finding
from .seaway import findings_model

FloatArray = NDArray[np.float64]
#: Length of the time windows shown for input effects and wave forcing, s.
WINDOW = 60.0
#: At most this many points in a scatter (evenly thinned).
MAX_POINTS = 4000
HOW_TO_READ = """\
The nominal model's extended Kalman smoother estimates every state over the record; the
*equation errors* are what its equations cannot explain from step to step (state units per
second). The channels, windows and band locate the mismatch in the model's 3 s-ahead predictions
(a channel's score is its share of the prediction error in excess of the sensor noise). Each
finding is a catalogue term fitted on the first 70 % of the record and kept only if it
significantly reduces the prediction error on the last 30 % (held out); its *confidence* is the
probability that it is real, shared with alternatives that explain the same thing, and its
*improvement* is the share of the held-out excess error it removes alone. In the figures, a
finding that is right brings the orange (after) curves down to the sensor noise across the
held-out part, flattens the spectra where the blue (before) ones rise above the rest, and its
fitted curve follows the cloud of equation errors."""


# -- the entry point ------------------------------------------------------------------------------
#: What :func:`write_report` writes into its folder (file names and patterns), both kinds of
#: record: a rerun over an older report clears exactly these.
OWNED = ("report.md", "diagnosis.json", "prediction_errors.png", "spectra.png",
         "finding_*.png", "time_histories.png", "simulation_errors.png", "extinction.png")


def owned_files(directory: str | Path) -> list[Path]:
    """The files of a report (:data:`OWNED`) in ``directory``."""
    directory = Path(directory)
    return sorted({p for pattern in OWNED for p in directory.glob(pattern) if p.is_file()})


def write_report(diagnosis: Diagnosis, directory: str | Path, recording_name: str = "") -> Path:
    """Write ``report.md``, its figures and ``diagnosis.json`` into ``directory`` (created).

    The report is made in a hidden folder inside ``directory`` first; only once all of it is
    written does it replace the earlier report's files (every one of :data:`OWNED`, so that
    no figure of an earlier run stays), ``report.md`` last. A full disk or an error on the
    way leaves the earlier report as it was, never half a new one beside it.

    :param diagnosis: the result of :func:`~estimators.diagnosis.diagnose`.
    :param directory: output folder; an earlier report in it is replaced.
    :param recording_name: shown in the title (e.g. the file name); default: the model's name.
    :returns: the path of ``report.md``.
    :raises marine_envs.files.WriteError: a file cannot be written (naming its place in
        ``directory``).
    """
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(prefix=".report.", suffix=".part",
                                         dir=directory) as staging:
            try:
                _write_into(diagnosis, Path(staging), recording_name)
            except OSError as error:  # name the file asked for, not its staging place
                raise WriteError(error.errno, str(error).replace(staging, str(directory)),
                                 str(directory)) from error
            for stale in owned_files(directory):
                stale.unlink()
            made = sorted(Path(staging).iterdir(), key=lambda p: p.name == "report.md")
            for path in made:
                os.replace(path, directory / path.name)
    except WriteError:
        raise
    except OSError as error:
        raise WriteError(error.errno, f"cannot write {directory}: {error.strerror or error}",
                         str(directory)) from error
    return directory / "report.md"


def _write_into(diagnosis: Diagnosis, directory: Path, recording_name: str) -> None:
    diagnosis.to_json(directory / "diagnosis.json")
    figures: list[tuple[str, str]] = []
    if diagnosis.comparison is not None:  # a model test, judged in free simulation
        figures = free_simulation_figures.write_figures(diagnosis, directory, recording_name)
    elif diagnosis.mismatch is not None and diagnosis.residuals is not None:
        figures = write_figures(diagnosis, directory)
    write_text(directory / "report.md", markdown(diagnosis, figures, recording_name))


def write_figures(diagnosis: Diagnosis, directory: Path) -> list[tuple[str, str]]:
    """Every figure of the report; ``(file name, caption)`` of those written."""
    figures = [plot_prediction_errors(diagnosis, directory / "prediction_errors.png"),
               plot_spectra(diagnosis, directory / "spectra.png")]
    selection = diagnosis.selection
    for k, scored in enumerate(selection.findings if selection else [], 1):
        effect = scored.fitted.effect
        name = slug(f"finding_{k}_{effect.effect}_{effect.target}") + ".png"
        figures.append(plot_finding(diagnosis, k - 1, directory / name))
    return [f for f in figures if f is not None]


# -- Markdown -------------------------------------------------------------------------------------
def markdown(diagnosis: Diagnosis, figures: Sequence[tuple[str, str]] = (),
             recording_name: str = "") -> str:
    """The report's text; ``figures`` are ``(relative file name, caption)`` pairs."""
    if diagnosis.comparison is not None:  # a model test, judged in free simulation
        return free_simulation_report.markdown(diagnosis, figures, recording_name)
    title = recording_name or diagnosis.model
    parts = [f"# Mismatch diagnosis: {cell(title)}", "",
             f"Model: `{diagnosis.model}`" + (f" · recording: `{recording_name}`"
                                              if recording_name else ""), "",
             "## Verdict", "", verdict(diagnosis), ""]
    if diagnosis.mismatch is None:
        return "\n".join(parts)
    parts += _calibration(diagnosis) + _location(diagnosis) + _findings(diagnosis.findings) \
        + _alternatives(diagnosis.alternatives) + _withdrawn(diagnosis.unconfirmed) \
        + _fit(diagnosis)
    if figures:
        parts += ["## Figures", ""]
        for name, caption in figures:
            parts += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    parts += ["## How to read this", "", HOW_TO_READ, "",
              "The full result is in [`diagnosis.json`](diagnosis.json).", ""]
    return "\n".join(parts)


def verdict(diagnosis: Diagnosis) -> str:
    """One paragraph: mismatch found, none, or cannot judge (with the reason)."""
    if diagnosis.mismatch is None:
        return f"**Cannot judge.** {diagnosis.reason}"
    if not diagnosis.mismatch:
        return ("**No significant mismatch.** The nominal model explains the record: no catalogue "
                "term significantly improves its held-out predictions."
                + (f" {diagnosis.reason}" if diagnosis.reason else ""))
    names = ", ".join(f"`{f.effect}` on `{f.target}`" for f in diagnosis.findings)
    return (f"**Mismatch found:** {names}; together they remove "
            f"{diagnosis.fit.get('improvement', 0):.0%} of the held-out prediction error in "
            "excess of the sensor noise.")


def _calibration(diagnosis: Diagnosis) -> list[str]:
    if not diagnosis.calibration:
        return []
    rows = [f"| {n} | {num(v)} |" for n, v in diagnosis.calibration.items()]
    return ["## Calibrated parameters", "", "| parameter | value |", "| --- | ---: |", *rows, ""]


def _location(diagnosis: Diagnosis) -> list[str]:
    """Channels with their scores, the windows and the band."""
    units = _units(diagnosis)
    rows = [f"| {c['name']} | {units.get(c['name'], '')} | {c['score']:.1%} |"
            for c in diagnosis.channels]
    out = ["## Where", "", "Share of the multi-step prediction error in excess of the sensor "
           "noise, per measured channel:", "", "| channel | unit | score |",
           "| --- | --- | ---: |", *rows, ""]
    if diagnosis.windows:
        spans = ", ".join(f"{w['start']:.0f}–{w['end']:.0f} s" for w in diagnosis.windows)
        out.append(f"Windows where the error in `{diagnosis.windows[0]['channel']}` "
                   f"concentrates: {spans}.")
    else:
        out.append("Windows: none (the error is spread over the record).")
    band = diagnosis.band
    out += ["", f"Band holding 80 % of the equation-error power: {band['low']:.3g}–"
            f"{band['high']:.3g} rad/s." if band else "Band: none located.", ""]
    return out


def _findings(findings: Sequence[Finding]) -> list[str]:
    """The findings table."""
    out = ["## Findings", ""]
    if not findings:
        return out + ["None: no catalogue term passed the held-out significance test.", ""]
    out += ["| # | effect | target | parameters (± std) | confidence | improvement | "
            "explanation |", "| ---: | --- | --- | --- | ---: | ---: | --- |"]
    for k, f in enumerate(findings, 1):
        out.append(f"| {k} | {f.effect} | {f.target} | {cell(parameters(f))} | "
                   f"{f.confidence:.2f} | {f.improvement:.0%} | {cell(f.explanation)} |")
    return out + [""]


def _alternatives(alternatives: Sequence[dict[str, Any]]) -> list[str]:
    """Terms the record supports as well as a finding, and what would separate them."""
    if not alternatives:
        return []
    out = ["Equally supported (neither term predicts what the other leaves; the record cannot "
           "choose):", ""]
    for alt in alternatives:
        values = ", ".join(f"{k} = {num(v)}" for k, v in alt["parameters"].items())
        out.append(f"- `{alt['chosen']}` (reported) or `{alt['equally']}` ({values}): to "
                   f"separate them, {alt['separate_by']}.")
    return out + [""]


def _withdrawn(unconfirmed: Sequence[Finding]) -> list[str]:
    """Terms the search accepted but the confirmation withdrew, each with the reason."""
    if not unconfirmed:
        return []
    return ["Withdrawn (significant on the innovations, not confirmed):", ""] + [
        f"- `{f.effect}` on `{f.target}` ({cell(parameters(f))}): "
        + (f.withdrawn or "refitted on the first part, it did not improve the held-out "
           "predictions") + "." for f in unconfirmed] + [""]


def _fit(diagnosis: Diagnosis) -> list[str]:
    """Held-out RMSE per channel before and after the findings."""
    before = diagnosis.fit.get("before", {}).get("rmse", {})
    after = diagnosis.fit.get("after", {}).get("rmse", {})
    if not before:
        return []
    units = _units(diagnosis)
    rows = [f"| {c} | {units.get(c, '')} | {num(b)} | {num(after.get(c, b))} | "
            f"{change(b, after.get(c, b))} |" for c, b in before.items()]
    return ["## Held-out fit", "", f"{diagnosis.fit.get('validation', '')}.", "",
            "| channel | unit | RMSE before | RMSE after | change |",
            "| --- | --- | ---: | ---: | ---: |", *rows, "",
            f"Combined improvement (share of the excess error removed): "
            f"{diagnosis.fit.get('improvement', 0):.0%}.", ""]


# -- figure (a): held-out prediction errors -------------------------------------------------------
def plot_prediction_errors(diagnosis: Diagnosis, path: Path) -> tuple[str, str] | None:
    """Per channel, the prediction error at the end of the horizon (channel units) against the
    start time (s): all starts before the findings (grey on the fit part), the held-out starts
    before (blue) and after (orange); ±1 sensor-noise std dotted; windows shaded."""
    ro, res = diagnosis.rollouts, diagnosis.residuals
    if ro is None or res is None:
        return None
    plt = pyplot()
    times = res.time[ro.starts]
    before = ro.nominal_error[:, -1, :]
    after = _after_error(diagnosis)
    units = _units(diagnosis)
    fig, axes = plt.subplots(len(res.channels), 1, sharex=True, squeeze=False,
                             figsize=(9, 1.9 * len(res.channels) + 0.8))
    for j, (ax, channel) in enumerate(zip(axes[:, 0], res.channels, strict=True)):
        ax.plot(times[~ro.held], before[~ro.held, j], color="0.7", lw=0.7, label="before, fit part")
        ax.plot(times[ro.held], before[ro.held, j], color="tab:blue", lw=0.8, label="before")
        if after is not None:
            ax.plot(times[ro.held], after[ro.held, j], color="tab:orange", lw=0.8,
                    label="after findings")
        for level in (-res.noise[j], res.noise[j]):
            ax.axhline(level, color="k", lw=0.6, ls=":")
        _shade_windows(ax, diagnosis.windows)
        ax.set_ylabel(f"{channel}\n({units.get(channel, '')})")
        ax.grid(alpha=0.3)
    if ro.held.any():
        for ax in axes[:, 0]:
            ax.axvline(times[ro.held][0], color="k", lw=0.8)
    axes[0, 0].legend(fontsize=8, ncol=4, loc="upper left")
    axes[-1, 0].set_xlabel("start time of the prediction (s)")
    fig.suptitle(f"{ro.steps * res.dt:.1f} s-ahead prediction error (measured - predicted)")
    save(fig, path)
    return path.name, (f"{ro.steps * res.dt:.1f} s-ahead prediction error per channel against "
                       "its start time; right of the black line: held out, before (blue) and "
                       "after (orange) the findings; dotted: ±1 sensor-noise std; shaded: "
                       "located windows")


def _after_error(diagnosis: Diagnosis) -> FloatArray | None:
    """Prediction error at the end of the horizon ``(S, m)`` with the findings, or None."""
    ro, selection = diagnosis.rollouts, diagnosis.selection
    if ro is None or selection is None or not selection.findings:
        return None
    assert diagnosis.residuals is not None
    effects, forcing, shift = findings_model(diagnosis.residuals,
                                             [s.fitted for s in selection.findings])
    return (ro.target - ro.predict(effects, forcing, shift))[:, -1, :]


def _shade_windows(ax: Any, windows: Sequence[dict[str, Any]]) -> None:
    for k, w in enumerate(windows):
        ax.axvspan(w["start"], w["end"], color="tab:red", alpha=0.12,
                   label="located window" if k == 0 else None)


# -- figure (b): spectra of the equation errors ---------------------------------------------------
def plot_spectra(diagnosis: Diagnosis, path: Path) -> tuple[str, str] | None:
    """Welch spectra ((state unit/s)^2 per rad/s) of the measured states' equation errors
    against the frequency (rad/s), before and after the findings' contributions; band shaded.
    None when no measured channel is a state (e.g. position outputs of the DP vessel)."""
    res = diagnosis.residuals
    if res is None:
        return None
    states = measured_states(res)
    if not states:
        return None
    plt = pyplot()
    after = res.error - total_contribution(diagnosis)
    fig, axes = plt.subplots(len(states), 1, sharex=True, squeeze=False,
                             figsize=(8, 1.9 * len(states) + 0.8))
    for ax, i in zip(axes[:, 0], states, strict=True):
        omega, psd = welch(res.error[:, i], res.dt)
        ax.loglog(omega[1:], psd[1:], color="tab:blue", lw=0.9, label="before")
        if diagnosis.findings:
            omega, psd = welch(after[:, i], res.dt)
            ax.loglog(omega[1:], psd[1:], color="tab:orange", lw=0.9, label="after findings")
        if diagnosis.band:
            ax.axvspan(diagnosis.band["low"], diagnosis.band["high"], color="tab:red",
                       alpha=0.1, label="located band")
        unit = _rate_unit(res.model.state_units[i])
        ax.set_ylabel(f"{res.model.state_names[i]}\n[{unit}]²·s/rad")
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8, loc="lower left")
    axes[-1, 0].set_xlabel("frequency (rad/s)")
    fig.suptitle("Spectra of the equation errors of the measured states")
    save(fig, path)
    return path.name, ("Welch spectra of the measured states' equation errors before (blue) "
                       "and after (orange) subtracting the findings' contributions; shaded: "
                       "the located band")


def measured_states(res: Residuals) -> list[int]:
    """Indices of the states that are measured channels."""
    return [i for i, name in enumerate(res.model.state_names) if name in res.channels]


def total_contribution(diagnosis: Diagnosis, skip: int | None = None) -> FloatArray:
    """Sum of the findings' contributions to the equation errors ``(T - 1, n)`` (state units
    per second), leaving out finding number ``skip`` (0-based)."""
    res, selection = diagnosis.residuals, diagnosis.selection
    assert res is not None
    total = np.zeros_like(res.error)
    for k, scored in enumerate(selection.findings if selection else []):
        if k != skip:
            total += scored.fitted.contribution
    return total


def welch(x: FloatArray, dt: float, segment: float = 60.0) -> tuple[FloatArray, FloatArray]:
    """Welch spectrum: angular frequencies (rad/s) and one-sided density per rad/s of ``x``
    sampled every ``dt`` s, ``segment`` s per segment (as the band's)."""
    f, psd = signal.welch(x, fs=1 / dt, nperseg=min(len(x), max(8, int(segment / dt))))
    return 2 * np.pi * f, psd / (2 * np.pi)


# -- figure (c): each finding's fitted term -------------------------------------------------------
def plot_finding(diagnosis: Diagnosis, k: int, path: Path) -> tuple[str, str] | None:
    """The fitted term of finding ``k`` (0-based) against the data it explains."""
    assert diagnosis.selection is not None
    effect = diagnosis.selection.findings[k].fitted.effect
    plot = {"state": _plot_state_term, "input": _plot_input_effect,
            "output": _plot_sensor_bias}[effect.kind]
    if effect.effect == "parameter_change":
        plot = _plot_parameter_change
    elif effect.effect == "wave_frequency":
        plot = _plot_wave_forcing
    plt = pyplot()
    fig, caption = plot(plt, diagnosis, k)
    fig.suptitle(f"finding {k + 1}: {effect.effect} on {effect.target}")
    save(fig, path)
    return path.name, f"Finding {k + 1} ({effect.effect} on {effect.target}): {caption}"


def _partial_error(diagnosis: Diagnosis, k: int, i: int) -> FloatArray:
    """Equation error of state ``i`` minus the other findings' contributions ``(T - 1,)``."""
    assert diagnosis.residuals is not None
    return diagnosis.residuals.error[:, i] - total_contribution(diagnosis, skip=k)[:, i]


def _plot_state_term(plt: Any, diagnosis: Diagnosis, k: int) -> tuple[Any, str]:
    """Scatter of the target's equation error against the term's regressor (the target state,
    the ``source`` state, or an ``unlisted`` product) with the fitted term as a curve."""
    res = diagnosis.residuals
    assert res is not None and diagnosis.selection is not None
    effect = diagnosis.selection.findings[k].fitted.effect
    model, x, u = res.model, res.midpoint, res.u[:-1]
    i = model.state_names.index(effect.target)
    if effect.effect == "unlisted":
        regressor = state_term(Effect("unlisted", effect.target, {**effect.parameters, "c": 1.0}),
                               model, x, u, res.time[:-1])
        label = f"{effect.parameters['expression']}"
    else:
        source = effect.parameters.get("source", effect.target)
        regressor = x[:, model.state_names.index(source)]
        label = f"{source} ({model.state_units[model.state_names.index(source)]})"
    term = state_term(effect, model, x, u, res.time[:-1])
    order = np.argsort(regressor)
    thin = _thin(len(regressor))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.scatter(regressor[thin], _partial_error(diagnosis, k, i)[thin], s=3, alpha=0.3,
               color="tab:blue", label="equation error")
    ax.plot(regressor[order], term[order], color="tab:orange", lw=2, label="fitted term")
    ax.set_xlabel(f"smoothed {label}")
    ax.set_ylabel(f"{effect.target} equation error {_rate_unit(model.state_units[i])}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig, (f"equation error of {effect.target} (other findings removed) against "
                 f"{label}, with the fitted term")


def _plot_input_effect(plt: Any, diagnosis: Diagnosis, k: int) -> tuple[Any, str]:
    """Commanded and applied input over the window where they differ most, and applied against
    commanded over the whole record."""
    res = diagnosis.residuals
    assert res is not None and diagnosis.selection is not None
    effect = diagnosis.selection.findings[k].fitted.effect
    j = res.model.input_names.index(effect.target)
    unit = res.model.input_units[j]
    commanded = res.u[:, j]
    applied = applied_inputs(effect, res.model, res.u, res.dt)[:, j]
    rows = _busiest_window(np.abs(applied - commanded), res.dt)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=(2, 1))
    left.plot(res.time[rows], commanded[rows], color="tab:blue", label="commanded")
    left.plot(res.time[rows], applied[rows], color="tab:orange", label="applied (fitted)")
    left.set_xlabel("time (s)")
    left.set_ylabel(f"{effect.target} ({unit})")
    left.legend(fontsize=8)
    thin = _thin(len(commanded))
    right.scatter(commanded[thin], applied[thin], s=3, alpha=0.4, color="tab:orange")
    right.plot(commanded, commanded, color="0.5", lw=0.8, ls="--")
    right.set_xlabel(f"commanded ({unit})")
    right.set_ylabel(f"applied ({unit})")
    for ax in (left, right):
        ax.grid(alpha=0.3)
    return fig, (f"commanded vs applied {effect.target} as the fitted effect makes it, over "
                 f"the {WINDOW:.0f} s where they differ most (left) and over the record (right)")


def _plot_sensor_bias(plt: Any, diagnosis: Diagnosis, k: int) -> tuple[Any, str]:
    """Top: the biased channel as measured and corrected (measured - b) against time. Bottom:
    the equation error the bias disturbs most, before and after its contribution, as 10 s
    running means (the steady offset the other channels contradict)."""
    res = diagnosis.residuals
    assert res is not None and diagnosis.selection is not None
    fitted = diagnosis.selection.findings[k].fitted
    effect, b = fitted.effect, fitted.effect.parameters["b"]
    j = res.channels.index(effect.target)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
    top.plot(res.time, res.y[:, j], color="tab:blue", lw=0.7, label="measured")
    top.plot(res.time, res.y[:, j] - b, color="tab:orange", lw=0.7, label=f"corrected (- {b:.3g})")
    top.axhline(0.0, color="k", lw=0.6)
    top.set_ylabel(f"{effect.target} ({_units(diagnosis).get(effect.target, '')})")
    i = _most_affected(res, fitted.contribution)
    n = max(1, int(round(10.0 / res.dt)))
    for values, color, label in ((_partial_error(diagnosis, k, i), "tab:blue", "before"),
                                 (_partial_error(diagnosis, k, i) - fitted.contribution[:, i],
                                  "tab:orange", "after the bias")):
        bottom.plot(res.time[:-1], _running_mean(values, n), color=color, lw=0.9, label=label)
    bottom.axhline(0.0, color="k", lw=0.6)
    bottom.set_ylabel(f"{res.model.state_names[i]} eq. error\n"
                      f"{_rate_unit(res.model.state_units[i])}, 10 s mean")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    return fig, (f"the {effect.target} channel as measured and with the fitted bias removed "
                 f"(top); the {res.model.state_names[i]} equation error it disturbs most, 10 s "
                 "running mean, before and after the bias (bottom)")


def _most_affected(res: Residuals, contribution: FloatArray) -> int:
    """The measured state whose equation a contribution changes most, relative to its error."""
    states = measured_states(res) or list(range(res.error.shape[1]))
    share = [np.sum(contribution[:, i] ** 2) / max(float(np.var(res.error[:, i])), 1e-300)
             for i in states]
    return states[int(np.argmax(share))]


def _running_mean(x: FloatArray, n: int) -> FloatArray:
    """Centred running mean over ``n`` samples (same length, shrinking at the ends)."""
    ones = np.ones(min(n, len(x)))
    return np.convolve(x, ones, mode="same") / np.convolve(np.ones(len(x)), ones, mode="same")


def _plot_parameter_change(plt: Any, diagnosis: Diagnosis, k: int) -> tuple[Any, str]:
    """The target's equation error against time with the fitted step term; change time marked,
    with its std."""
    res = diagnosis.residuals
    assert res is not None and diagnosis.selection is not None
    fitted = diagnosis.selection.findings[k].fitted
    effect, spread = fitted.effect, fitted.std.get("time", 0.0)
    i = res.model.state_names.index(effect.target)
    t = res.time[:-1]
    term = state_term(effect, res.model, res.midpoint, res.u[:-1], t)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(t, _partial_error(diagnosis, k, i), color="tab:blue", lw=0.5, label="equation error")
    ax.plot(t, term, color="tab:orange", lw=1.0, label="fitted term")
    ax.axvline(effect.parameters["time"], color="k", lw=1, ls="--", label="change time")
    ax.axvspan(effect.parameters["time"] - spread, effect.parameters["time"] + spread,
               color="k", alpha=0.12, lw=0, label="+- its std")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{effect.target} equation error {_rate_unit(res.model.state_units[i])}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig, (f"equation error of {effect.target} against time with the fitted term, which "
                 f"starts at t = {effect.parameters['time']:.1f} s (+- {spread:.1f} s)")


def _plot_wave_forcing(plt: Any, diagnosis: Diagnosis, k: int) -> tuple[Any, str]:
    """The target's equation error and the fitted narrow-band forcing over the window where the
    forcing is strongest."""
    res = diagnosis.residuals
    assert res is not None and diagnosis.selection is not None
    fitted = diagnosis.selection.findings[k].fitted
    effect = fitted.effect
    i = res.model.state_names.index(effect.target)
    forcing = np.asarray(fitted.details.get("forcing", fitted.contribution[:, i]))[:-1]
    rows = _busiest_window(np.abs(forcing), res.dt)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    ax.plot(res.time[rows], _partial_error(diagnosis, k, i)[rows], color="tab:blue", lw=0.7,
            label="equation error")
    ax.plot(res.time[rows], forcing[rows], color="tab:orange", lw=1.0, label="fitted forcing")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{effect.target} equation error {_rate_unit(res.model.state_units[i])}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    omega = effect.parameters["omega"]
    return fig, (f"equation error of {effect.target} and the fitted narrow-band forcing "
                 f"(ω = {omega:.3g} rad/s, period {2 * np.pi / omega:.3g} s) over "
                 f"{WINDOW:.0f} s")


def _busiest_window(weight: FloatArray, dt: float) -> slice:
    """The ``WINDOW``-second slice of samples with the largest sum of ``weight``."""
    n = min(len(weight), max(2, int(round(WINDOW / dt))))
    sums = np.convolve(weight, np.ones(n), mode="valid")
    start = int(np.argmax(sums)) if sums.size else 0
    return slice(start, start + n)


# -- helpers --------------------------------------------------------------------------------------
def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // MAX_POINTS))


def _units(diagnosis: Diagnosis) -> dict[str, str]:
    """SI unit of each output channel of the model (empty when the residuals are absent)."""
    if diagnosis.residuals is None:
        return {}
    model = diagnosis.residuals.model
    return dict(zip(model.output_names, model.output_units, strict=True))


def _rate_unit(unit: str) -> str:
    """The unit of a state's equation error: its unit per second, e.g. ``(rad/s)/s``."""
    return f"({unit})/s" if "/" in unit or " " in unit else f"{unit}/s"
