"""RGB frames of a vessel for ``render_mode="rgb_array"`` (and Gymnasium's RecordVideo).

Drawn with matplotlib's Agg backend into a reused figure, so no display or pygame is needed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..models import VehicleModel

# hull outlines in body axes (x forward, y starboard), metres of a notional 20 m boat
_HULL_TOP = np.array([[10, 0], [6, 3], [-9, 3], [-10, 2], [-10, -2], [-9, -3], [6, -3], [10, 0]])
_HULL_SECTION = np.array([[-4, 1.5], [-4, -0.5], [-2.5, -2], [2.5, -2], [4, -0.5], [4, 1.5],
                          [-4, 1.5]])


def _rotate(points: NDArray[np.float64], angle: float) -> NDArray[np.float64]:
    c, s = math.cos(angle), math.sin(angle)
    return points @ np.array([[c, s], [-s, c]])


class USVRenderer:
    """Top view (heading and rudder) and stern view (roll) of the USV, with a readout.

    :param model: the USV model (for state names and the rudder limit).
    :param size: frame size in pixels (width, height).
    """

    def __init__(self, model: VehicleModel, size: tuple[int, int] = (640, 320)) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.model = model
        dpi = 80
        self.figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        self.top, self.stern = self.figure.subplots(1, 2)
        self._setup()

    def _setup(self) -> None:
        for ax, title in ((self.top, "top view (north up)"), (self.stern, "from astern")):
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(title, fontsize=9)
        self.top.set_xlim(-14, 14)
        self.top.set_ylim(-14, 14)
        self.top.plot([0, 0], [-14, 14], color="0.85", lw=1)  # commanded course
        self.hull_top = self.top.fill([], [], color="tab:blue", alpha=0.8)[0]
        self.rudder, = self.top.plot([], [], color="tab:red", lw=3)
        self.stern.set_xlim(-7, 7)
        self.stern.set_ylim(-5, 5)
        self.stern.axhline(0, color="tab:cyan", lw=2)  # waterline
        self.hull_section = self.stern.fill([], [], color="tab:blue", alpha=0.8)[0]
        self.readout = self.figure.text(0.5, 0.02, "", ha="center", fontsize=9, family="monospace")

    def draw(self, x: NDArray[np.float64], u: NDArray[np.float64],
             time: float) -> NDArray[np.uint8]:
        """An RGB frame (height x width x 3) of state ``x`` and input ``u`` at ``time`` (s)."""
        names = self.model.state_names
        psi, phi, delta = x[names.index("psi")], x[names.index("phi")], u[0]
        # top view in (east, north): the hull points north at psi = 0 and turns clockwise with psi
        hull = _HULL_TOP[:, ::-1]
        self.hull_top.set_xy(_rotate(hull, -psi))
        # a positive rudder angle swings the trailing edge to port (the boat turns to port)
        rudder = np.array([[0.0, -10.0], [-3.0 * math.sin(delta), -10.0 - 3.0 * math.cos(delta)]])
        self.rudder.set_data(*_rotate(rudder, -psi).T)
        # seen from astern, starboard is on the right and positive roll lowers it
        self.hull_section.set_xy(_rotate(_HULL_SECTION, -phi))
        self.readout.set_text(f"t={time:6.1f} s  heading={math.degrees(psi):6.1f} deg  "
                              f"roll={math.degrees(phi):5.1f} deg  "
                              f"rudder={math.degrees(delta):5.1f} deg")
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        self.figure.clear()


class TimeSeriesRenderer:
    """Strip charts of the last ``window`` seconds of chosen states and of the inputs, for any
    vehicle: angles in degrees, other quantities in SI units.

    :param model: the vehicle model (names and units).
    :param states: names of the states to chart, one panel each (at most four are drawn).
    :param window: seconds of history shown.
    :param size: frame size in pixels (width, height).
    """

    def __init__(self, model: VehicleModel, states: tuple[str, ...], window: float = 60.0,
                 size: tuple[int, int] = (640, 480)) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.model, self.window = model, window
        self.states = [model.state_names.index(s) for s in states[:4]]
        dpi = 80
        self.figure = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = self.figure.subplots(len(self.states) + 1, 1, sharex=True)
        self.lines = []
        for ax, i in zip(self.axes, self.states, strict=False):
            self.lines.append(ax.plot([], [], color="tab:blue")[0])
            ax.set_ylabel(_label(model.state_names[i], model.state_units[i]), fontsize=8)
        self.input_lines = [self.axes[-1].plot([], [], label=name)[0]
                            for name in model.input_names]
        self.axes[-1].set_ylabel("inputs\n(% of range)", fontsize=8)
        self.axes[-1].set_xlabel("time (s)")
        self.axes[-1].legend(fontsize=7, loc="upper left", ncol=len(model.input_names))
        low, high = model.u_bounds
        self._u_mid, self._u_half = (high + low) / 2, (high - low) / 2
        self._times: list[float] = []
        self._x: list[NDArray[np.float64]] = []
        self._u: list[NDArray[np.float64]] = []

    def draw(self, x: NDArray[np.float64], u: NDArray[np.float64],
             time: float) -> NDArray[np.uint8]:
        """An RGB frame (height x width x 3) with the history up to ``time`` (s)."""
        if self._times and time <= self._times[-1]:  # a new episode
            self._times, self._x, self._u = [], [], []
        self._times.append(float(time))
        self._x.append(np.asarray(x, dtype=float).copy())
        self._u.append(100 * (np.asarray(u, dtype=float) - self._u_mid) / self._u_half)
        keep = next(k for k, t in enumerate(self._times) if t >= time - self.window)
        t = np.array(self._times[keep:])
        xs, us = np.array(self._x[keep:]), np.array(self._u[keep:])
        for line, i in zip(self.lines, self.states, strict=True):
            scale = 180 / math.pi if self.model.state_units[i].startswith("rad") else 1.0
            line.set_data(t, xs[:, i] * scale)
        for j, line in enumerate(self.input_lines):
            line.set_data(t, us[:, j])
        for ax in self.axes:
            ax.relim()
            ax.autoscale_view()
            ax.grid(alpha=0.3)
        self.axes[0].set_xlim(max(0.0, time - self.window), max(time, 1e-6))
        self.axes[0].set_title(f"{self.model.name}  t = {time:.1f} s", fontsize=9)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        self.figure.clear()


def _label(name: str, unit: str) -> str:
    return f"{name} ({unit.replace('rad', 'deg')})"
