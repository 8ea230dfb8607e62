"""What the rows say: the cost table and the orderings KF <= raw and true <= KF, ``summary.md``,
``cost_by_estimator.png``, ``degradation.png`` (when a degradation has several levels),
``rows.parquet`` (with pyarrow), and the self-contained HTML report (``--report DIR``)."""

from __future__ import annotations

import base64
import dataclasses
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from estimators.registry import ORACLE, RAW
from marine_envs.files import atomic_path, write_text
from marine_envs.provenance import save_figure

from .grid import DEGRADATIONS, KEYS, Grid, parse_sensor
from .run import ROWS

# -- what the rows say ---------------------------------------------------------------------------

def summary_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Cost mean and std over seeds per cell, with the number of failed episodes."""
    ok = rows[rows["status"] == "ok"]
    return (ok.groupby(list(KEYS), sort=False)
            .agg(cost=("cost", "mean"), spread=("cost", "std"), failed=("failed", "sum"),
                 episodes=("cost", "size")).reset_index())


def ordering(rows: pd.DataFrame, controller: str = "lqr") -> pd.DataFrame:
    """Per vehicle, sea and sensor: the mean costs of the true state, the KF and the raw
    sensors under ``controller``, and whether KF <= raw and true <= KF (LQR behind a KF that
    estimates the disturbances feeds them forward, which the true state alone cannot: it may
    beat the true state). Fewer failed episodes rank first; equal costs of episodes that failed
    are not comparable (None), nor is a row with an estimator missing. The cost of a cell whose
    every episode failed is NaN: a sum over truncated episodes is no cost to compare."""
    table = summary_table(rows)
    table = table[table["controller"] == controller]
    index = ["vehicle", "sea", "sensor"]
    wide = table.pivot_table(index=index, columns="estimator",
                             values=["cost", "failed", "episodes"], sort=False)
    out = pd.DataFrame(index=wide.index)
    for name in (ORACLE, "kf", RAW):
        for key, prefix in (("cost", ""), ("failed", "failed_"), ("episodes", "episodes_")):
            out[prefix + name] = wide[key][name] if name in wide[key] else np.nan
    records = out.to_dict("records")
    out["kf<=raw"] = [_ordered(r, ("kf", RAW)) for r in records]
    out["true<=kf"] = [_ordered(r, (ORACLE, "kf")) for r in records]
    for name in (ORACLE, "kf", RAW):  # after the verdicts, which count the failures
        out.loc[out[f"failed_{name}"] >= out[f"episodes_{name}"], name] = np.nan
    return out.drop(columns=[f"{p}_{n}" for n in (ORACLE, "kf", RAW)
                             for p in ("failed", "episodes")]).reset_index()


def _ordered(row: Mapping[str, float], names: Sequence[str]) -> bool | None:
    """Whether ``names`` are in order of (failures, cost); None if it cannot be told."""
    verdicts = []
    for a, b in zip(names, names[1:], strict=False):
        fa, fb = row[f"failed_{a}"], row[f"failed_{b}"]
        if np.isnan(row[a]) or np.isnan(row[b]):
            return None
        if fa != fb:
            verdicts.append(fa < fb)
        elif fa > 0:
            return None  # both failed as often: their truncated costs do not compare
        else:
            verdicts.append(row[a] <= row[b])
    return all(verdicts)


def _cell_text(cost: float, spread: float, failed: float, episodes: int) -> str:
    if failed >= episodes:  # truncated episodes only: their cost compares with nothing
        return f"all {episodes} failed"
    text = f"{cost:.4g} ± {0.0 if np.isnan(spread) else spread:.2g}"
    return text + (f" ({int(failed)}/{episodes} failed)" if failed else "")


COST_NOTE = ("Task cost: the environment's quadratic LQR cost summed over the episode (lower is "
             "better), mean ± std over seeds; n/a: the cell does not apply, or (orderings) "
             "cannot be told: a cell whose every episode failed has no cost.")
ORDER_TITLE = "KF <= raw sensors, true state <= KF (LQR)"


def _summary_frames(rows: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The cost table (estimators as columns), the ordering check, the cells that do not apply."""
    table = summary_table(rows)
    table["text"] = [_cell_text(*v) for v in
                     table[["cost", "spread", "failed", "episodes"]].itertuples(index=False)]
    wide = table.pivot_table(index=["vehicle", "sea", "sensor", "controller"],
                             columns="estimator", values="text", aggfunc="first", sort=False)
    wide = wide.reset_index().fillna("n/a")
    skipped = rows[rows["status"] != "ok"].drop_duplicates(subset=list(KEYS))
    reasons = [f"{' / '.join(str(r[k]) for k in KEYS)}: {r['status'][5:]}"
               for r in skipped.to_dict("records")]
    return wide, ordering(rows), reasons


def _cell(v: Any) -> str:
    """A table cell: numbers to 4 digits, "n/a" where there is nothing to tell (not "None"
    or "nan")."""
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "n/a"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _markdown_table(frame: pd.DataFrame) -> str:

    lines = ["| " + " | ".join(map(str, frame.columns)) + " |",
             "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(_cell(v) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return "\n".join(lines)


def markdown_summary(rows: pd.DataFrame) -> str:
    """The summary page: cost by estimator (columns) per vehicle, sea, sensor and controller,
    the ordering check, and the cells that do not apply."""
    wide, order, skipped = _summary_frames(rows)
    lines = ["# Estimator benchmark", "", COST_NOTE, "", _markdown_table(wide), ""]
    if len(order):
        lines += [f"## {ORDER_TITLE}", "", _markdown_table(order), ""]
    if skipped:
        lines += ["## Cells that do not apply", "", *[f"- {line}" for line in skipped], ""]
    return "\n".join(lines)


def plot_costs(rows: pd.DataFrame, path: Path) -> Path:
    """Cost by estimator per vehicle (bars per controller, std as error bars; log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summary_table(rows)
    table = table[(table["sea"] == table["sea"].iloc[0]) &
                  (table["sensor"] == table["sensor"].iloc[0])]
    vehicles = list(dict.fromkeys(table["vehicle"]))
    fig, axes = plt.subplots(1, len(vehicles), figsize=(3.2 * len(vehicles) + 1, 3.6),
                             squeeze=False)
    for ax, vehicle in zip(axes[0], vehicles, strict=True):
        part = table[table["vehicle"] == vehicle]
        estimators = list(dict.fromkeys(part["estimator"]))
        controllers = list(dict.fromkeys(part["controller"]))
        width = 0.8 / len(controllers)
        for j, controller in enumerate(controllers):
            sub = part[part["controller"] == controller].set_index("estimator")
            x = [i + j * width for i, e in enumerate(estimators) if e in sub.index]
            got = [e for e in estimators if e in sub.index]
            ax.bar(x, sub.loc[got, "cost"], width, yerr=sub.loc[got, "spread"].fillna(0),
                   label=controller, capsize=2)
        ax.set_xticks([i + 0.4 - width / 2 for i in range(len(estimators))], estimators,
                      rotation=45)
        ax.set_yscale("log")
        ax.set_title(vehicle)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("task cost")
    axes[0][-1].legend(fontsize=8)
    fig.suptitle(f"Cost by estimator (sea {table['sea'].iloc[0]}, sensors "
                 f"{table['sensor'].iloc[0]})")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_degradation(rows: pd.DataFrame, path: Path) -> Path | None:
    """Cost against the level of each single degradation (``default`` is level 1 of noise and
    0 of the others), per vehicle, a line per estimator under LQR; None with fewer than two
    levels of any kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summary_table(rows)
    controller = "lqr" if (table["controller"] == "lqr").any() else table["controller"].iloc[0]
    table = table[table["controller"] == controller]
    colours = {e: f"C{i}" for i, e in enumerate(dict.fromkeys(table["estimator"]))}
    levels = {s: parse_sensor(s) for s in table["sensor"].unique()}
    kinds = [k for k in DEGRADATIONS
             if len({lv.get(k, 1.0 if k == "noise" else 0.0)
                     for lv in levels.values() if set(lv) <= {k}}) >= 2]
    if not kinds:
        return None
    vehicles = list(dict.fromkeys(table["vehicle"]))
    fig, axes = plt.subplots(len(kinds), len(vehicles), squeeze=False,
                             figsize=(3.2 * len(vehicles) + 1, 3.0 * len(kinds)))
    for row, kind in enumerate(kinds):
        for ax, vehicle in zip(axes[row], vehicles, strict=True):
            part = table[(table["vehicle"] == vehicle)]
            for estimator in dict.fromkeys(part["estimator"]):
                sub = part[part["estimator"] == estimator]
                points = sorted((levels[s].get(kind, 1.0 if kind == "noise" else 0.0), c)
                                for s, c in zip(sub["sensor"], sub["cost"], strict=True)
                                if set(levels[s]) <= {kind})
                if len(points) >= 2:
                    ax.plot(*zip(*points, strict=True), marker="o", label=estimator,
                            color=colours[estimator])
            ax.set_yscale("log")
            ax.set_xlabel(kind)
            ax.set_title(vehicle)
            ax.grid(alpha=0.3)
        axes[row][0].set_ylabel("task cost")
    handles = {line.get_label(): line for ax in axes.flat for line in ax.get_lines()}
    fig.legend(handles.values(), handles.keys(), loc="upper right", fontsize=8)
    fig.suptitle(f"Degradation curves ({controller})")
    fig.tight_layout(rect=(0, 0, 0.92, 1))
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def write_outputs(rows: pd.DataFrame, out: Path) -> list[Path]:
    """``summary.md``, the figures and (with pyarrow) ``rows.parquet`` into ``out``."""
    written = [out / ROWS]
    try:
        with atomic_path(out / "rows.parquet") as temporary:
            rows.to_parquet(temporary, index=False)
        written.append(out / "rows.parquet")
    except ImportError:
        pass  # Parquet is optional: pip install 'marine-envs[parquet]'
    write_text(out / "summary.md", markdown_summary(rows))
    written.append(out / "summary.md")
    if (rows["status"] == "ok").any():
        written.append(plot_costs(rows, out / "cost_by_estimator.png"))
        degradation = plot_degradation(rows, out / "degradation.png")
        if degradation is not None:
            written.append(degradation)
    return written


def write_report(rows: pd.DataFrame, out: Path, report: Path, grid: Grid) -> Path:
    """One self-contained HTML page (``report/index.html``): the grid, the cost table, the
    ordering check, the cells that do not apply and the figures, inlined."""
    report = Path(report)
    report.mkdir(parents=True, exist_ok=True)
    wide, order, skipped = _summary_frames(rows)
    parts = ["<!doctype html><meta charset='utf-8'><title>marine bench</title>",
             "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}</style>",
             "<h1>Estimator benchmark</h1>",
             f"<p>Grid: {_html_escape(json.dumps(dataclasses.asdict(grid)))}</p>",
             f"<p>{COST_NOTE}</p>", wide.to_html(index=False)]
    if len(order):
        shown = order.astype(object).map(_cell)  # "n/a", not None / NaN
        parts += [f"<h2>{ORDER_TITLE}</h2>", shown.to_html(index=False)]
    if skipped:
        parts += ["<h2>Cells that do not apply</h2><ul>",
                  *[f"<li>{_html_escape(line)}</li>" for line in skipped], "</ul>"]
    for name in ("cost_by_estimator.png", "degradation.png"):
        if (out / name).exists():
            data = base64.b64encode((out / name).read_bytes()).decode()
            parts.append(f"<p><img src='data:image/png;base64,{data}' alt='{name}'></p>")
    page = report / "index.html"
    write_text(page, "\n".join(parts) + "\n")
    return page


def _html_escape(text: str) -> str:
    import html

    return html.escape(text)
