"""The report of a model-test diagnosis (free simulation, :mod:`.model_test`): text and figures.

:func:`.report.write_report` hands a diagnosis with a ``comparison`` to this module, which writes

* ``time_histories.png``: per run and measured channel, the measured record (black), the
  nominal model's free simulation (blue) and the model with the findings (orange), angles in
  degrees; the held-out part of a single record shaded;
* ``simulation_errors.png``: measured minus simulated for both models, sensor noise dotted;
* ``extinction.png`` (free decays only): logarithmic decrement per period and period against
  mean amplitude, measured and simulated by both models;

and the text of ``report.md``: verdict, model check, calibrated parameters, findings (with each
equation's standard form), held-out free simulation, alternatives, what is left unexplained,
the figures and how to read them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .api import Diagnosis, Finding
from .comparison import Comparison
from .model_test import standard_form
from .modes import MODE_TOLERANCE, Decay, decay_analysis, free_decays, model_modes
from .output_error import Fit, fit
from .report import _cell, _num, _pyplot, _save

FloatArray = NDArray[np.float64]
#: At most this many subplots in the time histories (run and channel pairs).
MAX_PANELS = 6
#: Lines longer than this are thinned (every k-th sample) before plotting.
MAX_LINE_POINTS = 20_000
MEASURED, NOMINAL, CORRECTED = "black", "tab:blue", "tab:orange"
MARKERS = ("o", "s", "^", "D", "v", "P")
#: The terms of the standard form, in order, and what they multiply.
STANDARD_TERMS = (("B1", "{x}"), ("B2", "{x}|{x}|"), ("B3", "{x}³"), ("C1", "{q}"),
                  ("C3", "{q}³"))


# -- figures --------------------------------------------------------------------------------------
def write_figures(diagnosis: Diagnosis, directory: str | Path,
                  recording_name: str = "") -> list[tuple[str, str]]:
    """Every figure of a model-test report; ``(file name, caption)`` of those written."""
    comparison: Comparison | None = diagnosis.comparison
    if comparison is None:
        return []
    directory = Path(directory)
    labels = run_labels(comparison, recording_name)
    predicted = _simulations(comparison, held_out=len(comparison.series.runs) == 1)
    figures = [plot_time_histories(comparison, predicted, labels,
                                   directory / "time_histories.png"),
               plot_simulation_errors(comparison, predicted, labels,
                                      directory / "simulation_errors.png")]
    whole = predicted if len(comparison.series.runs) > 1 else _simulations(comparison, False)
    figures.append(plot_extinction(comparison, whole, labels, directory / "extinction.png"))
    return [f for f in figures if f is not None]


def _simulations(comparison: Comparison, held_out: bool) -> list[dict[str, FloatArray]]:
    """Per run, the free simulations ``(T, m)`` of the measured channels: ``"nominal"`` and,
    when terms were accepted, ``"corrected"`` (the final model). ``held_out``: each model
    refitted on the first ``fit_fraction`` of a single record, as its held-out score is
    computed (the rest is predicted); otherwise the fits to all data."""
    fits = {"nominal": comparison.nominal}
    if comparison.accepted:
        fits["corrected"] = comparison.final
    out: list[dict[str, FloatArray]] = [{} for _ in comparison.series.runs]
    for key, model_fit in fits.items():
        theta = model_fit.theta
        if held_out:
            run = comparison.series.runs[0]
            theta = fit(model_fit.structure, [_fit_part(comparison, run.time)], theta).theta
        for r in range(len(comparison.series.runs)):
            out[r][key] = model_fit.structure.simulate(theta, r)[0]
    return out


def _fit_part(comparison: Comparison, time: FloatArray) -> NDArray[np.bool_]:
    """The samples of a single record the held-out score fits on (the rest is predicted)."""
    return time < time[0] + comparison.config.fit_fraction * (time[-1] - time[0])


def run_labels(comparison: Comparison, recording_name: str = "") -> list[str]:
    """A label per run: its name, else the recording names given (comma-separated, one per
    run), else ``run k``."""
    runs = comparison.series.runs
    given = [n.strip() for n in recording_name.split(",")] if recording_name else []
    if len(given) != len(runs):
        given = [recording_name] if len(runs) == 1 and recording_name else []
    return [run.name or (given[k] if given else f"run {k + 1}") for k, run in enumerate(runs)]


def _panels(comparison: Comparison) -> tuple[list[tuple[int, int]], int]:
    """The (run, channel) pairs drawn (at most :data:`MAX_PANELS`) and how many there are."""
    series = comparison.series
    pairs = [(r, j) for r in range(len(series.runs)) for j in range(len(series.channels))]
    return pairs[:MAX_PANELS], len(pairs)


def plot_time_histories(comparison: Comparison, simulated: Sequence[dict[str, FloatArray]],
                        labels: Sequence[str], path: Path) -> tuple[str, str] | None:
    """Measured (black), nominal (blue) and corrected (orange) time histories per run and
    channel, in display units (angles in degrees); the held-out part of one record shaded.
    With at most two run-channel pairs, each also gets a zoom on the record's first and last
    few periods (where a decay's large and small amplitudes show the models apart)."""
    series = comparison.series
    pairs, total = _panels(comparison)
    if not pairs:
        return None
    zoom = len(pairs) <= MAX_PANELS // 3
    plt = _pyplot()
    rows = len(pairs) * (2 if zoom else 1)
    fig = plt.figure(figsize=(11, (2.2 if zoom else 2.1) * rows + 0.9))
    grid = fig.add_gridspec(rows, 2)
    first = None
    for k, (r, j) in enumerate(pairs):
        run, channel = series.runs[r], series.channels[j]
        name = _channel_name(channel, labels[r], len(series.runs))
        row = 2 * k if zoom else k
        ax = fig.add_subplot(grid[row, :])
        first = first or ax
        _draw_history(ax, comparison, simulated[r], r, j, (run.time[0], run.time[-1]))
        ax.set_ylabel(f"{name}\n({display_unit(channel_units(comparison).get(channel, ''))[1]})")
        if not zoom:
            continue
        length = _zoom_length(comparison, r, j)
        for col, (a, b, where) in enumerate((
                (run.time[0], run.time[0] + length, "first"),
                (run.time[-1] - length, run.time[-1], "last"))):
            sub = fig.add_subplot(grid[row + 1, col])
            _draw_history(sub, comparison, simulated[r], r, j, (a, b))
            sub.set_title(f"{name}: the {where} {length:.3g} s", fontsize=9)
            sub.set_xlabel("time (s)")
    assert first is not None
    first.legend(fontsize=8, ncol=4, loc="upper right")
    fig.suptitle("Free simulation against the record")
    _save(fig, path)
    return path.name, ("Measured (black), " + _caption_models(comparison)
                       + (" Below each record, zooms on its first and last periods."
                          if zoom else "") + _caption_shown(total, len(pairs)))


def _draw_history(ax: Any, comparison: Comparison, simulated: dict[str, FloatArray], r: int,
                  j: int, span: tuple[float, float]) -> None:
    """One channel of one run over ``span`` (s): measured and simulated, display units."""
    series = comparison.series
    run = series.runs[r]
    factor, _ = display_unit(channel_units(comparison).get(series.channels[j], ""))
    inside = np.flatnonzero((run.time >= span[0]) & (run.time <= span[1]))
    rows = inside[::_stride(len(inside))]
    t, measured = run.time[rows], run.y[rows, j] * factor
    ax.plot(t, measured, color=MEASURED, lw=1.3, label="measured")
    for key, color, label in (("nominal", NOMINAL, "nominal model"),
                              ("corrected", CORRECTED, "with the findings")):
        if key in simulated:
            ax.plot(t, simulated[key][rows, j] * factor, color=color, lw=0.9, label=label)
    _limit(ax, measured)
    if len(series.runs) == 1:
        _shade_held_out(ax, comparison, run.time)
    ax.set_xlim(*span)
    ax.grid(alpha=0.3)


def _zoom_length(comparison: Comparison, r: int, j: int) -> float:
    """Five periods of the run's free decay in channel ``j``, else a tenth of the run; at most
    a quarter of it."""
    run = comparison.series.runs[r]
    channel = comparison.series.channels[j]
    decay = free_decays(run.time, run.u, run.y, run.noise, comparison.series.channels).get(channel)
    length = 5 * decay.period if decay is not None else 0.1 * run.duration
    return float(min(length, 0.25 * run.duration))


def plot_simulation_errors(comparison: Comparison, simulated: Sequence[dict[str, FloatArray]],
                           labels: Sequence[str], path: Path) -> tuple[str, str] | None:
    """Measured minus simulated per run and channel, nominal (blue) and corrected (orange);
    ±1 sensor-noise std dotted; the held-out part of one record shaded."""
    series = comparison.series
    pairs, total = _panels(comparison)
    if not pairs:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(pairs), 1, squeeze=False, figsize=(11, 1.8 * len(pairs) + 0.9))
    for ax, (r, j) in zip(axes[:, 0], pairs, strict=True):
        run, channel = series.runs[r], series.channels[j]
        factor, unit = display_unit(channel_units(comparison).get(channel, ""))
        step = _stride(len(run.time))
        t = run.time[::step]
        for key, color, label in (("nominal", NOMINAL, "nominal model"),
                                  ("corrected", CORRECTED, "with the findings")):
            if key in simulated[r]:
                error = (run.y[::step, j] - simulated[r][key][::step, j]) * factor
                ax.plot(t, error, color=color, lw=0.8, label=label)
        for level in (-run.noise[j], run.noise[j]):
            ax.axhline(level * factor, color="k", lw=0.7, ls=":", zorder=1)
        ax.axhline(0.0, color="0.4", lw=0.5, zorder=1)
        measured = run.y[::step, j] * factor
        _limit(ax, measured - np.mean(measured))  # a diverged simulation is cut off
        if len(series.runs) == 1:
            _shade_held_out(ax, comparison, run.time)
        ax.set_xlim(run.time[0], run.time[-1])
        ax.set_ylabel(f"{_channel_name(channel, labels[r], len(series.runs))} error\n({unit})")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=3, loc="upper right")
    axes[-1, 0].set_xlabel("time from the start of the record (s)")
    fig.suptitle("Free-simulation error (measured - simulated)")
    _save(fig, path)
    return path.name, ("Free-simulation error (measured - simulated) of the simulations of "
                       "the time histories: nominal model (blue)" + (
                           ", with the findings (orange)" if comparison.accepted else "")
                       + "; dotted: ±1 sensor-noise std"
                       + ("; shaded: held out (predicted)" if len(series.runs) == 1 else "")
                       + ". Angles in degrees." + _caption_shown(total, len(pairs)))


def _caption_models(comparison: Comparison) -> str:
    """How the simulations of the time-history figures were made, honestly."""
    models = "nominal model (blue)" + (" and the model with the findings (orange)"
                                       if comparison.accepted else "")
    if len(comparison.series.runs) == 1:
        fraction = comparison.config.fit_fraction
        each = "each fitted" if comparison.accepted else "fitted"
        return (f"{models}, {each} on the first {fraction:.0%} of the record (calibrated "
                f"parameters, terms and initial states) and simulated freely from the start: "
                f"the shaded last {1 - fraction:.0%} is predicted, not fitted (the held-out "
                "test of the table). Angles in degrees.")
    return (f"{models} in free simulation, fitted to all recordings of the series. The "
            "held-out scores of the table predict each recording with the model fitted on the "
            "others; these all-data fits are not those predictions. Angles in degrees.")


def _caption_shown(total: int, shown: int) -> str:
    return f" The first {shown} of {total} run-channel pairs shown." if total > shown else ""


def _channel_name(channel: str, label: str, runs: int) -> str:
    return f"{label}: {channel}" if runs > 1 else channel


def _shade_held_out(ax: Any, comparison: Comparison, time: FloatArray) -> None:
    """Shade the held-out part of a single record (never past its end)."""
    start = float(time[0] + comparison.config.fit_fraction * (time[-1] - time[0]))
    if start < time[-1]:
        ax.axvspan(start, float(time[-1]), color="0.85", alpha=0.6, lw=0,
                   label="held out (predicted)")


def _limit(ax: Any, reference: FloatArray) -> None:
    """Keep the y-range near ``reference`` when a simulation runs off (diverges)."""
    finite = reference[np.isfinite(reference)]
    if not finite.size:
        return
    low, high = float(finite.min()), float(finite.max())
    span = max(high - low, 1e-12)
    bottom, top = ax.get_ylim()
    ax.set_ylim(max(bottom, low - 1.5 * span), min(top, high + 1.5 * span))


def _stride(n: int) -> int:
    return max(1, math.ceil(n / MAX_LINE_POINTS))


def plot_extinction(comparison: Comparison, simulated: Sequence[dict[str, FloatArray]],
                    labels: Sequence[str], path: Path) -> tuple[str, str] | None:
    """For each channel with a free decay: logarithmic decrement per period and period against
    the mean amplitude, measured (black) and simulated by the nominal (blue) and corrected
    (orange) models; None when no run holds a free decay."""
    series = comparison.series
    decays = decay_table(comparison, simulated)
    if not decays:
        return None
    channels = sorted({j for _, j in decays})[:3]
    plt = _pyplot()
    fig, axes = plt.subplots(len(channels), 2, squeeze=False,
                             figsize=(11, 3.6 * len(channels) + 0.6))
    styles = (("measured", MEASURED, "measured", "-"), ("nominal", NOMINAL, "nominal model", "--"),
              ("corrected", CORRECTED, "with the findings", "-"))
    for row, j in enumerate(channels):
        channel = series.channels[j]
        factor, unit = display_unit(channel_units(comparison).get(channel, ""))
        left, right = axes[row]
        for (r, jj), by_model in decays.items():
            if jj != j:
                continue
            marker = MARKERS[r % len(MARKERS)]
            run = f" ({labels[r]})" if len(series.runs) > 1 else ""
            for key, color, label, style in styles:
                decay = by_model.get(key)
                if decay is None or len(decay.amplitudes) < 3:
                    continue
                amplitude, decrement = decay.extinction()
                _, period = decay.periods()
                kwargs = {"color": color, "marker": marker, "ms": 4 if key == "measured" else 3,
                          "lw": 0.0 if key == "measured" else 1.0, "ls": style,
                          "label": label + run}
                left.plot(amplitude * factor, decrement, **kwargs)
                right.plot(amplitude * factor, period, **kwargs)
        left.set_ylabel("log decrement per period (-)")
        right.set_ylabel("period (s)")
        for ax in (left, right):
            ax.set_xlabel(f"mean amplitude of {channel} ({unit})")
            ax.set_xlim(left=0)
            ax.grid(alpha=0.3)
        left.set_ylim(bottom=min(0.0, left.get_ylim()[0]))
        low, high = right.get_ylim()
        middle, half = 0.5 * (low + high), max(0.5 * (high - low), 0.02 * 0.5 * (low + high))
        right.set_ylim(middle - half, middle + half)  # at least ±2 %: sampling jitter stays small
        left.legend(fontsize=8)
    fig.suptitle("Extinction curves of the free decay")
    _save(fig, path)
    shown = ", ".join(series.channels[j] for j in channels)
    return path.name, (f"Extinction curves of the free decay of {shown}: logarithmic "
                       "decrement ln(a_k / a_k+2) per period (left) and period (right) against "
                       "the mean amplitude of the period (angles in degrees); measured (black "
                       "dots), nominal model (blue)" + (" and model with the findings (orange)"
                                                        if comparison.accepted else "")
                       + (", both" if comparison.accepted else ",")
                       + " fitted to all data and simulated freely; read down to five "
                       "sensor-noise deviations. A flat decrement is linear damping, one "
                       "rising with amplitude is nonlinear damping; a period changing with "
                       "amplitude is nonlinear restoring.")


def decay_table(comparison: Comparison, simulated: Sequence[dict[str, FloatArray]]
                ) -> dict[tuple[int, int], dict[str, Decay | None]]:
    """Per (run, channel) whose measured record is a free decay (inputs held): its
    :class:`Decay` and those of the simulations (``None`` where a simulation does not decay),
    read with the run's noise (:func:`.modes.decay_analysis`)."""
    series = comparison.series
    out: dict[tuple[int, int], dict[str, Decay | None]] = {}
    for r, run in enumerate(series.runs):
        if run.u.size and np.any(np.ptp(run.u, axis=0) > 0):
            continue  # an input moves: not a free decay
        for j in range(len(series.channels)):
            noise = float(run.noise[j])
            measured = decay_analysis(run.time, run.y[:, j], noise)
            if measured is None:
                continue
            row: dict[str, Decay | None] = {"measured": measured}
            for key, y in simulated[r].items():
                row[key] = decay_analysis(run.time, y[:, j], noise) \
                    if np.all(np.isfinite(y[:, j])) else None
            out[(r, j)] = row
    return out


# -- units ----------------------------------------------------------------------------------------
def channel_units(comparison: Comparison) -> dict[str, str]:
    model = comparison.series.model
    return dict(zip(model.output_names, model.output_units, strict=True))


def display_unit(unit: str) -> tuple[float, str]:
    """The factor to the display unit and its name: angles (rad, rad/s, ...) in degrees."""
    if unit == "rad":
        return 180 / math.pi, "deg"
    if unit.startswith("rad/"):
        return 180 / math.pi, "deg/" + unit[len("rad/"):]
    return 1.0, unit


def _with_degrees(value: float, unit: str) -> str:
    """``value`` in its SI unit, with the degrees in brackets for an angle."""
    factor, shown = display_unit(unit)
    text = _num(float(value))
    return text + (f" ({float(value) * factor:.3g} {shown})" if factor != 1.0 else "")


# -- Markdown -------------------------------------------------------------------------------------
def markdown(diagnosis: Diagnosis, figures: Sequence[tuple[str, str]] = (),
             recording_name: str = "") -> str:
    """The text of a model-test report; ``figures`` are ``(relative file name, caption)``."""
    comparison: Comparison | None = diagnosis.comparison
    title = recording_name or diagnosis.model
    runs = len(comparison.series.runs) if comparison is not None else 1
    parts = [f"# Mismatch diagnosis: {_cell(title)}", "",
             f"Model: `{diagnosis.model}`" + (f" · recording{'s' if runs > 1 else ''}: "
                                              f"`{recording_name}`" if recording_name else "")
             + " · method: free simulation (model test)", "",
             "## Verdict", "", verdict(diagnosis), ""]
    if comparison is None or diagnosis.mismatch is None:
        return "\n".join(parts + _model_check(diagnosis, comparison))
    parts += _model_check(diagnosis, comparison) + _calibration(diagnosis, comparison) \
        + _findings(diagnosis, comparison) + _held_out(diagnosis, comparison) \
        + _alternatives(diagnosis) + _unexplained(diagnosis, comparison)
    if figures:
        parts += ["## Figures", ""]
        for name, caption in figures:
            parts += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    parts += ["## How to read this", "", how_to_read(comparison), "",
              "The full result is in [`diagnosis.json`](diagnosis.json).", ""]
    return "\n".join(parts)


def verdict(diagnosis: Diagnosis) -> str:
    """One paragraph: mismatch found (and whether something is left), no mismatch, a mismatch
    the catalogue does not explain, or cannot judge (with the reason)."""
    if diagnosis.mismatch is None:
        return f"**Cannot judge.** {diagnosis.reason}"
    left = _left_over(diagnosis)
    if diagnosis.findings:
        names = ", ".join(f"`{f.effect}` on `{f.target}`" for f in diagnosis.findings)
        improvement = diagnosis.fit.get("improvement")
        gain = ("; but the model with them diverges in the held-out free simulation, so their "
                "combined gain cannot be measured" if improvement == "diverged" else
                f"; {'together they remove' if len(diagnosis.findings) > 1 else 'it removes'} "
                f"{_percent(improvement)} of the held-out free-simulation error in excess of "
                "the sensor noise")
        return (f"**Mismatch found:** the model lacks {names}{gain}."
                + (f" **Still unexplained:** {left}." if left else
                   " What is left is within the sensor noise."))
    if diagnosis.mismatch:
        return ("**Mismatch, unexplained by the catalogue:** the calibrated model does not "
                "simulate the held-out data within the sensor noise" + (f" ({left})" if left
                                                                        else "")
                + ", and no catalogue term removes enough of the difference.")
    return ("**No significant mismatch.** The calibrated nominal model simulates the held-out "
            "data within the sensor noise; no catalogue term is needed."
            + (f" {diagnosis.reason}" if diagnosis.reason else ""))


def _left_over(diagnosis: Diagnosis) -> str:
    """``"RMS x in phi (y % of the signal)"`` per unexplained channel."""
    units = _units(diagnosis)
    return "; ".join(f"RMS {_with_degrees(v['rmse'], units.get(c, ''))} in `{c}` "
                     f"({_percent(v['share_of_signal'])} of the signal's RMS)"
                     for c, v in diagnosis.unexplained.items())


def _units(diagnosis: Diagnosis) -> dict[str, str]:
    return channel_units(diagnosis.comparison) if diagnosis.comparison is not None else {}


def _model_check(diagnosis: Diagnosis, comparison: Comparison | None) -> list[str]:
    """The record's mode (natural frequency, damping ratio, period) against the model's."""
    check = diagnosis.model_check
    out = ["## Model check", ""]
    if not check:
        if comparison is None:
            return []
        return out + ["No free decay in the record (an input moves, or fewer than two periods "
                      "rise above the noise): the modes were not checked.", ""]
    record = check["record"]
    channel = _decay_channel(comparison)
    first = ", first recording" if comparison is not None and len(comparison.series.runs) > 1 \
        else ""
    rows = [f"| record{f' (decay of `{channel}`{first})' if channel else ''} | "
            f"{record['omega_n']:.4g} | {record['zeta']:.4g} | {record['period']:.4g} |"]
    for k, mode in enumerate(check.get("model", []), 1):
        rows.append(f"| model as set, mode {k} | {mode['omega_n']:.4g} | {mode['zeta']:.4g} | "
                    f"{_period(mode['omega_n'], mode['zeta'])} |")
    calibrated = _calibrated_modes(diagnosis, comparison)
    for k, (omega, zeta) in enumerate(calibrated, 1):
        rows.append(f"| calibrated model, mode {k} | {omega:.4g} | {zeta:.4g} | "
                    f"{_period(omega, zeta)} |")
    out += ["The record's own mode, read from the extrema of the free decay (period from the "
            "zero crossings, damping from the logarithmic decrement of the first periods), "
            "against the observable modes of the linearised model:", "",
            "| | natural frequency (rad/s) | damping ratio | damped period (s) |",
            "| --- | ---: | ---: | ---: |", *rows, ""]
    if check.get("matches"):
        out.append("The model as set has a mode at the record's natural frequency (within "
                   f"{MODE_TOLERANCE:.0%}).")
    else:
        out.append(f"**The model as set does not match:** {check.get('advice', '')}."
                   + (" The calibration started from the record's mode." if calibrated else ""))
    return out + [""]


def _decay_channel(comparison: Comparison | None) -> str:
    """The channel whose decay the model check read (the first decaying one)."""
    if comparison is None:
        return ""
    series = comparison.series
    for run in series.runs:
        decays = free_decays(run.time, run.u, run.y, run.noise, series.channels)
        if decays:
            return next(iter(decays))
    return ""


def _calibrated_modes(diagnosis: Diagnosis, comparison: Comparison | None
                      ) -> list[tuple[float, float]]:
    """The observable modes of the model with its calibrated parameters (none when nothing was
    calibrated)."""
    if comparison is None or not diagnosis.calibration:
        return []
    model = comparison.series.model.with_params(**diagnosis.calibration)
    return model_modes(model, comparison.series.channels)


def _period(omega: float, zeta: float) -> str:
    return f"{2 * math.pi / (omega * math.sqrt(1 - zeta**2)):.4g}" \
        if 0 < zeta < 1 and omega > 0 else ("∞" if omega == 0 else "– (not oscillatory)")


def _calibration(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """Calibrated parameters: as set, fitted ± std, refitted with the findings, verdict; the
    correlations the records cannot resolve."""
    quality = diagnosis.calibration_quality
    parameters = quality.get("parameters", {})
    if not parameters:
        return []
    final = comparison.final
    with_terms = bool(comparison.accepted)
    labels = final.structure.labels()
    header = "| parameter | as set | calibrated (± std) |" + (" with the findings (± std) |"
                                                              if with_terms else "") \
        + " status |"
    rows = []
    for name, q in parameters.items():
        row = (f"| {name} | {_num(float(getattr(comparison.series.model.params, name)))} | "
               f"{_num(q['value'])} ± {_num(q['std'])} |")
        if with_terms:
            k = labels.index(name)
            row += f" {_num(float(final.theta[k]))} ± {_num(float(final.std[k]))} |"
        rows.append(row + f" {_cell(q['status'])} |")
    out = ["## Calibrated parameters", "",
           "Fitted by output error (free simulation of "
           + ("every recording" if len(comparison.series.runs) > 1 else "the whole record")
           + "), standard deviations "
           "from the residuals' effective number of independent samples"
           + ("; the last value column is the final model's, refitted with the accepted terms"
              if with_terms else "") + ":", "", header,
           "| --- | ---: | ---: |" + (" ---: |" if with_terms else "") + " --- |", *rows, ""]
    if not quality.get("converged", True):
        out += ["**The solver did not converge:** treat these values with care.", ""]
    correlations = quality.get("correlations", [])
    if correlations:
        out += [f"Correlated: {' and '.join(c['parameters'])} ({c['correlation']:+.3f}): "
                f"{c['status']}." for c in correlations] + [""]
    else:
        out += ["No pair of calibrated parameters is correlated beyond ±0.98: the records "
                "tell them apart.", ""]
    return out


def _findings(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """The findings table and the final model's equations in standard form."""
    out = ["## Findings", ""]
    if not diagnosis.findings:
        return out + ["None: no catalogue term removed enough of the held-out free-simulation "
                      "error.", ""]
    out += ["Terms accepted one at a time, each refitted together with the calibrated "
            "parameters and the terms before it; a row's parameters and standard form are "
            "those of the model at the round its term was accepted.", "",
            "| # | effect | target | parameters (± std) | standard form | confidence | "
            "improvement | explanation |",
            "| ---: | --- | --- | --- | --- | ---: | ---: | --- |"]
    for k, f in enumerate(diagnosis.findings, 1):
        form = ", ".join(f"{key} = {_num(f.standard_form[key])}" for key, _ in STANDARD_TERMS
                         if key in f.standard_form)
        out.append(f"| {k} | {f.effect} | {f.target} | {_cell(_parameters(f))} | {form} | "
                   f"{f.confidence:.2f} | {_percent(f.improvement)} | "
                   f"{_cell(f.explanation)} |")
    out += ["", "Final model, all terms refitted together on all data (per unit inertia):", ""]
    notes = []
    for target in dict.fromkeys(f.target for f in diagnosis.findings):
        equation = _equation(comparison.final, target, diagnosis.findings)
        if equation:
            out.append(f"    {equation}")
            notes += _sign_notes(comparison.final, target)
    out += ["", *_final_values(comparison.final), *notes]
    return out


def _sign_notes(final: Fit, target: str) -> list[str]:
    """A warning per negative damping or restoring coefficient of the final equation."""
    form = standard_form(final, target)
    words = {"B1": "linear damping", "B2": "quadratic damping", "B3": "cubic damping",
             "C1": "linear restoring"}
    out = [f"**Note:** {key} < 0 in the equation of `{target}`: negative {word}. Alone it "
           "would feed the motion; here it only reshapes the other terms over the amplitudes "
           "recorded, do not extrapolate it." for key, word in words.items()
           if form.get(key, 0.0) < 0]
    return [line for note in out for line in (note, "")]


def _parameters(finding: Finding) -> str:
    items = []
    for name, value in finding.parameters.items():
        std = finding.std.get(name)
        items.append(f"{name} = {_num(value)}" + (f" ± {_num(std)}" if std is not None else ""))
    return ", ".join(items)


def _equation(final: Fit, target: str, findings: Sequence[Finding]) -> str:
    """``target' = -B1 x - B2 x|x| - ...`` with the final fit's numbers (signs folded in)."""
    model = final.structure.series.model
    if target not in model.state_names:
        return ""
    form = standard_form(final, target)
    source = next((f.parameters["source"] for f in findings
                   if f.target == target and "source" in f.parameters), None)
    if source is None and "C1" in form:
        A = model.linearize()[0]
        i = model.state_names.index(target)
        sources = [q for q in np.flatnonzero(A[i]) if q != i]
        source = model.state_names[sources[-1]] if sources else "q"
    terms = []
    for key, shape in STANDARD_TERMS:
        if form.get(key, 0.0) != 0.0:
            value = -form[key]
            terms.append(f"{'-' if value < 0 else '+'} {abs(value):.4g} "
                         f"{shape.format(x=target, q=source)}")
    if not terms:
        return ""
    others = [t for t in final.structure.terms if t.target == target and t.effect not in
              ("linear_damping", "quadratic_damping", "nonlinear_damping", "coupling",
               "nonlinear_restoring")]
    joined = " ".join(terms)
    text = f"{target}' = " + (joined[2:] if joined.startswith("+") else "-" + joined[2:])
    extra = (" + (other terms)" if others else "") \
        + (" + (inputs)" if final.structure.series.moving.any() else "")
    return text + extra


def _final_values(final: Fit) -> list[str]:
    """The final fit's parameters and term coefficients (initial states left out)."""
    structure = final.structure
    count = len(structure.names) + len(structure.terms)
    labels = structure.labels()[:count]
    if not labels:
        return []
    rows = [f"| `{label}` | {_num(float(final.theta[k]))} | {_num(float(final.std[k]))} |"
            for k, label in enumerate(labels)]
    return ["| unknown of the final model | value | std |", "| --- | ---: | ---: |", *rows, ""]


def _held_out(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    """Held-out free-simulation RMS per channel before and after, the validation sentence and
    the combined improvement."""
    fit_ = diagnosis.fit
    before = fit_.get("before", {}).get("rmse", {})
    after = fit_.get("after", {}).get("rmse", {})
    noise = fit_.get("noise_rmse", {})
    if not before:
        return []
    units = _units(diagnosis)
    rows = []
    for c, b in before.items():
        unit = units.get(c, "")
        shown = display_unit(unit)[1]
        a = after.get(c, b)
        rows.append(f"| {c} | {unit}" + (f" ({shown})" if shown != unit else "") + " | "
                    f"{_with_degrees(noise[c], unit) if c in noise else '–'} | "
                    f"{_with_degrees(b, unit)} | {_with_degrees(a, unit)} | {_change(b, a)} |")
    improvement = fit_.get("improvement")
    combined = ("the model with the findings **diverged** in the held-out free simulation"
                if improvement == "diverged" else
                f"{_percent(improvement)} of the held-out error in excess of the sensor noise "
                "removed")
    return ["## Held-out free simulation", "",
            f"Validation: {fit_.get('validation', '')}.", "",
            "| channel | unit | sensor noise (RMS) | RMS before | RMS after | change |",
            "| --- | --- | ---: | ---: | ---: | ---: |", *rows, "",
            f"Combined improvement: {combined}." if comparison.accepted else
            "No term was accepted: the calibrated nominal model is the final model.", ""]


def _alternatives(diagnosis: Diagnosis) -> list[str]:
    if not diagnosis.findings:
        return []
    out = ["## Alternatives", ""]
    if not diagnosis.alternatives:
        comparison = diagnosis.comparison
        tie = comparison.config.tie if comparison is not None else 0.1
        return out + [f"None: every accepted term beat the other candidates of its round by "
                      f"more than {tie:.0%} of the held-out error.", ""]
    out += ["Terms the held-out data cannot tell apart (within "
            f"{diagnosis.comparison.config.tie:.0%} of the held-out error); the chosen one "
            "is reported, the other would do as well:", ""]
    for alt in diagnosis.alternatives:
        out.append(f"- `{alt['chosen']}` (chosen) or `{alt['equally']}`: to separate them, "
                   f"{alt['separate_by']}.")
    return out + [""]


def _unexplained(diagnosis: Diagnosis, comparison: Comparison) -> list[str]:
    out = ["## Unexplained", ""]
    factor = comparison.config.noise_factor
    if not diagnosis.unexplained:
        return out + [f"Nothing: the final model's held-out error is within {factor:g}× the "
                      "sensor noise.", ""]
    units = _units(diagnosis)
    rows = [f"| {c} | {_with_degrees(v['rmse'], units.get(c, ''))} | "
            f"{_percent(v['share_of_signal'])} |" for c, v in diagnosis.unexplained.items()]
    return out + [f"The final model's held-out free-simulation error stays above {factor:g}× "
                  "the sensor noise: physics neither the model nor the catalogue holds (or a "
                  "term whose coefficient changes between the fitted and held-out parts).", "",
                  "| channel | RMS held-out error | share of the signal's RMS |",
                  "| --- | ---: | ---: |", *rows, ""]


def how_to_read(comparison: Comparison) -> str:
    """The method in a paragraph, with this comparison's configuration."""
    config = comparison.config
    held = (f"the last {1 - config.fit_fraction:.0%} of the record, predicted by continuing the "
            f"simulation fitted on the first {config.fit_fraction:.0%} (for a decay: the small "
            "amplitudes the fit did not see)" if len(comparison.series.runs) == 1 else
            "each recording, predicted by the model fitted on the others (only its own initial "
            "state fitted to it)")
    return f"""\
**Free simulation.** The model starts where the record starts (its initial states fitted) and
is driven by the recorded inputs only, never corrected by the measurements: the whole time
history must come out of its equations. A model right only over a few seconds or at one
amplitude fails this test. The calibrated parameters, the terms' coefficients and the initial
states are fitted by least squares on the whole history (output error). A catalogue term is
added, everything refitted, and the term kept only when it removes at least
{config.min_gain:.0%} of the error in excess of the sensor noise on data no fit has seen:
{held}. Each finding's *improvement* is its share of that excess error; its *confidence* falls
with its coefficient's relative standard deviation and halves when a competitor explains the
data as well (see Alternatives).

**Standard form.** Each force equation with a finding is written per unit inertia as
`x' = -B1 x - B2 x|x| - B3 x^3 - C1 q - C3 q^3` (+ inputs), x the state of the equation (the
roll rate p for roll) and q its restoring source (the roll angle phi): B1 linear, B2 quadratic
and B3 cubic damping; C1 linear restoring (the natural frequency squared) and C3 cubic
restoring (C3 > 0 stiffening: the period shortens with amplitude; C3 < 0 softening). A
negative B lowers the damping at large amplitude; next to another damping form it usually
trades off with it over the amplitudes recorded.

**Figures.** In the time histories a right model's orange curve lies on the black record in
the shaded (held-out) part too; the errors should shrink to the dotted noise band. On the
extinction curves, linear damping gives a flat logarithmic decrement, quadratic damping one
rising linearly with amplitude, cubic one rising with its square; a constant period is linear
restoring. The corrected model should follow the measured points down to small amplitudes."""


def _percent(value: Any) -> str:
    return f"{value:.0%}" if isinstance(value, int | float) and not isinstance(value, bool) \
        else str(value)


def _change(before: float, after: float) -> str:
    return f"{(after - before) / before:+.0%}" if before > 0 else "–"

