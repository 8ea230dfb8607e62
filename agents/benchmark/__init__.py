"""``marine bench``: which estimator helps which controller how much, on every vehicle.

A grid of vehicles x estimators x sea states x sensor degradations x controllers x seeds
(:mod:`.grid`). Each cell runs its seeds as one batch through :func:`agents.evaluation.evaluate`,
so every controller is scored on the same episodes and the same quadratic cost; cells run in
local processes or as Ray tasks, and finished cells are kept in ``rows.csv`` (:mod:`.run`).
``summary.md``, the figures and the HTML report say what the rows say (:mod:`.report`).
"""

from .grid import (
    CONTROLLERS,
    DEGRADATIONS,
    KEYS,
    SB3_ALGOS,
    SEAS,
    TRAINING_SEED,
    VEHICLES,
    Grid,
    cell_key,
    parse_sensor,
    sensor_kwargs,
)
from .report import (
    COST_NOTE,
    ORDER_TITLE,
    markdown_summary,
    ordering,
    plot_costs,
    plot_degradation,
    summary_table,
    write_outputs,
    write_report,
)
from .run import ROWS, Task, load_rows, run_cell, run_grid, run_local, run_ray, train_agent

__all__ = [
    "CONTROLLERS", "COST_NOTE", "DEGRADATIONS", "KEYS", "ORDER_TITLE", "ROWS", "SB3_ALGOS",
    "SEAS", "TRAINING_SEED", "VEHICLES", "Grid", "Task", "cell_key", "load_rows",
    "markdown_summary", "ordering", "parse_sensor", "plot_costs", "plot_degradation",
    "run_cell", "run_grid", "run_local", "run_ray", "sensor_kwargs", "summary_table",
    "train_agent", "write_outputs", "write_report",
]
