"""The zig-zag rudder law of the ITTC Z-test (:mod:`marine_envs.manoeuvres`) for a batch of
boats, :class:`ZigzagRudder`: what :func:`~marine_envs.manoeuvres.zigzag` steers with, and any
caller that overrides a rudder with the test (an environment's zig-zag task)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..models.base import FloatArray, VehicleModel

#: Input names recognised as the rudder, state names recognised as the heading, in order.
RUDDER_NAMES = ("delta", "delta_r", "rudder")
HEADING_NAMES = ("psi",)


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Angle wrapped to [-pi, pi), rad."""
    return (np.asarray(angle, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def _index(names: tuple[str, ...], wanted: tuple[str, ...], index: int | None, what: str,
           model: VehicleModel) -> int:
    if index is not None:
        if not 0 <= index < len(names):
            raise ValueError(f"{what}_index={index!r} is invalid: model {model.name!r} has "
                             f"{len(names)} ({', '.join(names)})")
        return index
    for name in wanted:
        if name in names:
            return names.index(name)
    raise ValueError(f"model {model.name!r} has no {what} ({' or '.join(wanted)}) among "
                     f"{', '.join(names)}; pass {what}_index")


class ZigzagRudder:
    """Vectorised zig-zag rudder state machine for a batch of boats (ITTC Z-test).

    Per boat it keeps the initial heading, the current rudder direction (+1 starboard, -1 port)
    and the number of rudder reversals. Call it each control step with the headings; it returns
    the rudder angles to apply (open loop, e.g. to override an agent's rudder action).

    :param amplitude: rudder amplitude A, rad (> 0); scalar or one per boat.
    :param switch: heading change B at which the rudder reverses, rad (> 0); scalar or per boat.
    :param batch_size: number of boats.
    :param first_direction: +1 (default, starboard first as ITTC) or -1 (port first).
    :param turn_sign: +1 (default) when a positive rudder turns the heading positive (SNAME
        convention, e.g. the hovercraft), -1 for models with the opposite sign (the USV).
    :param rudder_rate: rudder rate limit, rad/s; ``None`` (default) moves it instantaneously.
    :param rudder_index: position of the rudder in the input vector, for :meth:`apply`.
    :param heading_index: position of the heading in the state vector, for :meth:`apply`.
    """

    def __init__(self, amplitude: ArrayLike, switch: ArrayLike, batch_size: int = 1, *,
                 first_direction: int = 1, turn_sign: int = 1, rudder_rate: float | None = None,
                 rudder_index: int | None = None, heading_index: int | None = None) -> None:
        if not (isinstance(batch_size, (int, np.integer)) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: must be an integer >= 1")
        self.batch_size = int(batch_size)
        for name, value in (("amplitude", amplitude), ("switch", switch)):
            arr = np.asarray(value, dtype=float)
            if not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
                raise ValueError(f"{name}={value!r} is invalid: must be finite and > 0 rad")
            try:
                arr = np.broadcast_to(arr, (self.batch_size,)).copy()
            except ValueError:
                raise ValueError(f"{name} has shape {arr.shape}; need a scalar or "
                                 f"({self.batch_size},)") from None
            setattr(self, name, arr)
        if first_direction not in (1, -1):
            raise ValueError(f"first_direction={first_direction!r} is invalid: +1 or -1")
        if turn_sign not in (1, -1):
            raise ValueError(f"turn_sign={turn_sign!r} is invalid: +1 or -1")
        if rudder_rate is not None and not (math.isfinite(rudder_rate) and rudder_rate > 0):
            raise ValueError(f"rudder_rate={rudder_rate!r} is invalid: must be > 0 rad/s or None")
        self.first_direction, self.turn_sign = first_direction, turn_sign
        self.rudder_rate = rudder_rate
        self.rudder_index, self.heading_index = rudder_index, heading_index
        self.initial_heading = np.zeros(self.batch_size)
        self.direction = np.full(self.batch_size, float(first_direction))
        self.reversals = np.zeros(self.batch_size, dtype=int)
        self.rudder = np.zeros(self.batch_size)
        self.reset()

    def reset(self, idx: Any = None, initial_heading: ArrayLike = 0.0,
              initial_rudder: ArrayLike = 0.0) -> None:
        """Start the test for boats ``idx`` (index, slice, mask or ``None`` = all).

        :param initial_heading: heading at the first execute, rad: a scalar, one per selected boat
            or one per boat of the batch.
        :param initial_rudder: rudder angle before the execute, rad; used only with a rate limit
            (without one the rudder is at ``first_direction * A`` at once).
        """
        sel = slice(None) if idx is None else idx
        heading = np.asarray(initial_heading, dtype=float)
        n_selected = self.initial_heading[sel].size
        if heading.shape == (self.batch_size,) and n_selected != self.batch_size:
            heading = heading[idx]  # one heading per boat of the whole batch: take the selected
        self.initial_heading[sel] = heading
        self.direction[sel] = self.first_direction
        self.reversals[sel] = 0
        if self.rudder_rate is None:
            self.rudder[sel] = self.first_direction * self.amplitude[sel]
        else:
            self.rudder[sel] = initial_rudder

    def heading_change(self, heading: ArrayLike) -> FloatArray:
        """Heading change from the initial heading, wrapped to [-pi, pi), rad."""
        return wrap_angle(np.asarray(heading, dtype=float) - self.initial_heading)

    def __call__(self, heading: ArrayLike, dt: float | None = None) -> FloatArray:
        """Rudder angle per boat, rad, for the current headings (rad, shape ``(batch_size,)``).

        :param dt: time since the previous call, s; needed only with a rudder rate limit.
        """
        change = self.heading_change(heading)
        # the rudder reverses once the heading has turned B the way the rudder drives it
        reverse = (self.turn_sign * self.direction) * change >= self.switch
        self.direction = np.where(reverse, -self.direction, self.direction)
        self.reversals += reverse
        target = self.direction * self.amplitude
        if self.rudder_rate is None:
            self.rudder = target
        else:
            if dt is None:
                raise ValueError("dt is needed with a rudder rate limit")
            step = self.rudder_rate * dt
            self.rudder = self.rudder + np.clip(target - self.rudder, -step, step)
        return self.rudder.copy()

    def apply(self, x: ArrayLike, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """Inputs ``u`` (shape ``(batch_size, n_u)``) with the rudder column replaced by the
        zig-zag command for states ``x`` (shape ``(batch_size, n_x)``)."""
        if self.rudder_index is None or self.heading_index is None:
            raise ValueError("apply needs rudder_index and heading_index")
        u = np.array(u, dtype=float)
        u[..., self.rudder_index] = self(np.asarray(x)[..., self.heading_index], dt)
        return u
