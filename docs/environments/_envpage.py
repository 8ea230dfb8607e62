"""Tables of an environment page, read from the code when the docs build, so a page cannot drift.

Each environment page calls :func:`spaces` and :func:`arguments` in a hidden executed cell.
:func:`arguments` fails the build when the environment gains, loses or renames an option the page
does not describe.
"""

from __future__ import annotations

import importlib
import inspect
import math

import gymnasium as gym
import numpy as np
from IPython.display import Markdown

import marine_envs
from marine_envs.envs.base import MarineEnv
from marine_envs.envs.core import SensorOptions

SENSOR_OPTIONS = tuple(SensorOptions.__annotations__)
#: Sensor options in the channel's unit (the others count control steps, samples or a probability).
PHYSICAL_OPTIONS = ("noise_std", "bias", "quantization", "sensor_range")


def _module(env_id: str):
    module, _prefix, _steps = marine_envs.ENVIRONMENTS[env_id]
    return importlib.import_module(f"marine_envs.envs.{module}")


def _units(model) -> dict[str, str]:
    """SI unit of every state and measured output of ``model``, by name."""
    return dict(zip(model.output_names, model.output_units, strict=True))


def _number(value: float) -> str:
    return f"{value:.4g}"


def spaces(env_id: str) -> Markdown:
    """Action and observation spaces, channels, units, period and episode length of ``env_id``."""
    env = gym.make(env_id)
    system, steps = env.unwrapped.system, env.spec.max_episode_steps
    model = system.model
    low, high = model.u_bounds
    units = _units(model)
    inputs = ", ".join(f"`{n}` {_number(lo)} ... {_number(hi)} {u}" for n, lo, hi, u in
                       zip(model.input_names, low, high, model.input_units, strict=True))
    channels = ", ".join(f"`{c}` ({units.get(c, '')}, +-{_number(r)})" for c, r in
                         zip(system.sensors.channels, system.sensors.output_range, strict=True))
    rows = [
        ("Import", f'`gym.make("{env_id}")`'),
        ("Action space", f"`{env.action_space}`"),
        ("Action, physical (mapped linearly from -1 ... 1)", inputs),
        ("Observation space",
         f"`Box({env.observation_space.shape}, {env.observation_space.dtype})`"),
        ("Observed channels (unit, full scale)", channels),
        ("True state (`info[\"state\"]`)", ", ".join(f"`{n}`" for n in model.state_names)),
        ("Control period `dt`", f"{env.unwrapped.dt} s"),
        ("Episode length", f"{steps} steps ({steps * env.unwrapped.dt:g} s)"),
    ]
    env.close()
    return _table(("", "from the code"), rows)


def arguments(env_id: str, meanings: dict[str, str]) -> Markdown:
    """The keyword arguments of ``env_id`` with their defaults (from the code) and ``meanings``.

    :param meanings: what each vehicle-specific argument is, with its unit; the sensor options
        and ``render_mode``/``effects`` are described once on the page and need no entry.
    :raises ValueError: an argument of the environment without a meaning, or a meaning for an
        argument the environment does not have.
    """
    module = _module(env_id)
    simulator = next(v for v in vars(module).values()
                     if isinstance(v, type) and issubclass(v, MarineEnv) and v is not MarineEnv
                     ).make_simulator
    parameters = {name: p.default for name, p in inspect.signature(simulator).parameters.items()
                  if p.kind is inspect.Parameter.KEYWORD_ONLY}
    missing = sorted(set(parameters) - set(meanings))
    extra = sorted(set(meanings) - set(parameters))
    if missing or extra:
        raise ValueError(f"{env_id}: arguments without a meaning on the page {missing}; "
                         f"meanings of arguments the environment does not have {extra}")
    rows = [(f"`{name}`", _default(default), meanings[name])
            for name, default in parameters.items()]
    return _table(("argument", "default", "meaning"), rows)


def sensor_defaults(env_id: str) -> Markdown:
    """The default sensor settings of ``env_id`` per channel (SI units; angles also in deg)."""
    defaults = _module(env_id).DEFAULT_SENSORS
    env = gym.make(env_id)
    channels, units = env.unwrapped.system.channels, _units(env.unwrapped.model)
    env.close()
    options = [o for o in SENSOR_OPTIONS if o in defaults]
    rows = []
    for channel in channels:
        cells = []
        for option in options:
            value = defaults[option]
            value = value.get(channel) if isinstance(value, dict) else value
            unit = units[channel] if option in PHYSICAL_OPTIONS else ""
            cells.append("-" if value is None else _with_degrees(value, unit))
        rows.append((f"`{channel}`", *cells))
    return _table(("channel", *options), rows)


def _with_degrees(value: float, unit: str) -> str:
    if not unit:
        return _number(value)
    if unit.startswith("rad"):
        return f"{_number(value)} {unit} ({_number(math.degrees(value))} deg{unit[3:]})"
    return f"{_number(value)} {unit}"


def _default(value) -> str:
    if value is inspect.Parameter.empty:
        return "required"
    if isinstance(value, float):
        return f"`{_number(value)}`"
    if isinstance(value, (tuple, list)):
        return "`" + repr(tuple(float(v) if isinstance(v, (np.floating, float)) else v
                                for v in value)) + "`"
    return f"`{value!r}`"


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]]) -> Markdown:
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|") for c in row) + " |" for row in rows]
    return Markdown("\n".join(lines))
