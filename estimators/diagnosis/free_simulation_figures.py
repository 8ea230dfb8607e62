"""The figures of a model-test report (:mod:`.free_simulation_report`), written by
:func:`~estimators.diagnosis.free_simulation_figures.write_figures`:

* ``time_histories.png``: per run and measured channel, the measured record (black), the
  nominal model's free simulation (blue) and the model with the findings (orange), angles in
  degrees; the held-out part of a single record shaded;
* ``simulation_errors.png``: measured minus simulated for both models, sensor noise dotted;
* ``extinction.png`` (free decays only): logarithmic decrement per period and period against
  mean amplitude, measured and simulated by both models.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .comparison import Comparison
from .modes import Decay, decay_analysis, free_decays
from .report_format import num, pyplot, save
from .result import Diagnosis

FloatArray = NDArray[np.float64]
#: At most this many subplots in the time histories (run and channel pairs).
MAX_PANELS = 6
#: Lines longer than this are thinned (every k-th sample) before plotting.
MAX_LINE_POINTS = 20_000
MEASURED, NOMINAL, CORRECTED = "black", "tab:blue", "tab:orange"
MARKERS = ("o", "s", "^", "D", "v", "P")


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
    fits = {"nominal": (comparison.nominal, comparison.nominal_held_out)}
    if comparison.accepted:
        fits["corrected"] = (comparison.final, comparison.final_held_out)
    out: list[dict[str, FloatArray]] = [{} for _ in comparison.series.runs]
    for key, (model_fit, score) in fits.items():
        theta = score.theta if held_out and score.theta is not None else model_fit.theta
        for r in range(len(comparison.series.runs)):
            out[r][key] = model_fit.structure.simulate(theta, r)[0]
    return out


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
    plt = pyplot()
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
    save(fig, path)
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
    plt = pyplot()
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
    save(fig, path)
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
    plt = pyplot()
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
    save(fig, path)
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


def with_degrees(value: float, unit: str) -> str:
    """``value`` in its SI unit, with the degrees in brackets for an angle."""
    factor, shown = display_unit(unit)
    text = num(float(value))
    return text + (f" ({float(value) * factor:.3g} {shown})" if factor != 1.0 else "")


