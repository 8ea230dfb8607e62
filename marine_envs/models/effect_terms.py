"""The effect catalogue compiled: state terms added to a model's equations, input effects run
one sample at a time per boat (:mod:`marine_envs.models.effects` describes the catalogue).

Written once, on one boat's scalars, as each model's equations are: :func:`with_terms` makes a
model's equations plus the terms of a table packed after its constants (so the numpy ``rhs``,
the environments' step kernel and RK4 all run the same terms), and :func:`actuate` runs the
input effects of one boat (what :class:`~marine_envs.models.effects.BatchActuators` calls for a
batch and the step kernel for each boat). Each term is its numpy expression
(:func:`~marine_envs.models.effects.state_term`, the sample-by-sample input effects they
replaced) operation by operation, so both give the same numbers to the last bit.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..compiled import Equations, jit

#: State terms by code: ``c`` times 1, ``x_t``, ``x_t |x_t|``, ``x_t^3``, ``x_s``, ``x_s^3`` or
#: a product of states and inputs (``unlisted``).
CURRENT, LINEAR, QUADRATIC, CUBIC, SOURCE, SOURCE_CUBIC, PRODUCT = range(7)
STATE_CODES = {"current": CURRENT, "linear_damping": LINEAR, "quadratic_damping": QUADRATIC,
               "nonlinear_damping": CUBIC, "coupling": SOURCE, "nonlinear_restoring": SOURCE_CUBIC,
               "unlisted": PRODUCT}
#: Input effects by code.
GAIN, DELAY, SATURATION, DEADZONE, RATE_LIMIT = range(5)
INPUT_CODES = {"input_gain": GAIN, "input_delay": DELAY, "input_saturation": SATURATION,
               "input_deadzone": DEADZONE, "input_rate_limit": RATE_LIMIT}
#: Each input effect's parameter, as :func:`actuate` reads it (``tau`` becomes samples, ``rate``
#: a change per sample: :func:`~marine_envs.models.effects.input_table`).
INPUT_PARAMETER = {"input_gain": "k", "input_delay": "tau", "input_saturation": "limit",
                   "input_deadzone": "width", "input_rate_limit": "rate"}


# -- state terms ----------------------------------------------------------------------------------
@jit
def add_terms(x, u, p, out):
    """Add to ``out`` (one boat's ``x_dot``) the state terms of the table at the end of ``p``
    (:func:`~marine_envs.models.effects.term_table`), in its order. (The codes are compared as
    the floats they are stored as: converting each to an integer first made the USV's RK4 step
    with one term 1.6x the nominal one's, instead of 1.3x.)"""
    end = p.size - 1
    k = end - int(p[end])
    while k < end:
        code, target, c, n = p[k], int(p[k + 1]), p[k + 2], int(p[k + 3])
        if code == QUADRATIC:
            xt = x[target]
            term = c * xt * abs(xt)
        elif code == LINEAR:
            term = c * x[target]
        elif code == CURRENT:
            term = c
        elif code == CUBIC:  # math.pow: numpy's x**3 (a product of three rounds differently)
            term = c * math.pow(x[target], 3.0)
        elif code == SOURCE:
            term = c * x[int(p[k + 4])]
        elif code == SOURCE_CUBIC:
            term = c * math.pow(x[int(p[k + 4])], 3.0)
        else:
            term = c
            for j in range(n):
                operand = int(p[k + 4 + j])
                term = term * (x[operand] if operand >= 0 else u[-operand - 1])
        out[target] += term
        k += 4 + n


@functools.cache
def with_terms(equations: Equations) -> Equations:
    """A model's equations plus the state terms tabled after its constants (:func:`add_terms`);
    made once per process for each model's equations, compiled once per machine."""
    core = equations.core

    @jit
    def core_with_terms(x, u, d, p, out):
        core(x, u, d, p, out)
        add_terms(x, u, p, out)

    return Equations(core_with_terms)


# -- input effects --------------------------------------------------------------------------------
@jit
def actuate(kinds, inputs, u0, values, lengths, line, count, previous, b, u):
    """Boat ``b``'s applied inputs: its commanded ones ``u`` through the input effects, in
    place. Each effect acts on the deviation from the nominal input; ``line[b, s]`` is effect
    s's delay line (a ring), ``count[b, s]`` the samples it has seen (0: this is the first, a
    rate limit starts from it), ``previous[b, s]`` a rate limit's last output."""
    for s in range(kinds.size):
        j, nominal, value = inputs[s], u0[s], values[s]
        c = u[j] - nominal
        n = count[b, s]
        kind = kinds[s]
        if kind == DELAY:
            a = _delayed(line[b, s], lengths[s], n, c, value)
        elif kind == RATE_LIMIT:
            last = c if n == 0 else previous[b, s]
            change = c - last  # Python's min(max(change, -value), value)
            if -value > change:
                change = -value
            if value < change:
                change = value
            a = last + change
            previous[b, s] = a
        else:  # through the whole-sequence form, as ActuatorStream took it
            a = (nominal + _static(kind, c, value)) - nominal
        count[b, s] = n + 1
        u[j] = nominal + a


@jit(inline="never")  # once per step: compiled once, not into every caller
def actuate_boats(kinds, inputs, u0, values, lengths, line, count, previous, boats, u):
    """:func:`actuate` for boats ``boats`` (row r of ``u`` is boat ``boats[r]``'s)."""
    for r in range(boats.size):
        actuate(kinds, inputs, u0, values, lengths, line, count, previous, boats[r], u[r])


@jit
def _static(kind, c, value):
    """A memoryless input effect of deviation ``c``: numpy's ``k * c``, ``clip`` and dead
    zone (``sign(c) * maximum(abs(c) - width, 0)``), NaN as numpy."""
    if kind == GAIN:
        return value * c
    if kind == SATURATION:
        low = -value
        clipped = c if (np.isnan(c) or c > low) else low
        return clipped if (np.isnan(clipped) or clipped < value) else value
    magnitude = abs(c) - value
    if not (magnitude >= 0.0 or np.isnan(magnitude)):
        magnitude = 0.0
    sign = 1.0 if c > 0 else (-1.0 if c < 0 else (0.0 if c == 0 else c))
    return sign * magnitude


@jit
def _delayed(ring, length, n, c, samples):
    """Write ``c`` as sample ``n`` of a delay line and read it ``samples`` samples late: the last
    value of numpy's ``interp(arange(m) - samples, arange(m), window)`` over the last ``m =
    min(n + 1, length)`` samples (the first held before the start), step for step."""
    head = n % length
    ring[head] = c
    m = min(n + 1, length)
    start = head - m + 1  # the window's oldest sample, as a ring index
    x = (m - 1) - max(samples, 0.0)
    if m == 1 or x < 0.0:
        return ring[start % length]
    j = int(math.floor(x))
    low = ring[(start + j) % length]
    if j >= m - 1 or x == j:
        return low
    high = ring[(start + j + 1) % length]
    slope = (high - low) / 1.0
    value = slope * (x - j) + low
    if np.isnan(value):  # numpy tries the other end
        value = slope * (x - (j + 1)) + high
        if np.isnan(value) and low == high:
            value = low
    return value


__all__ = ["INPUT_CODES", "INPUT_PARAMETER", "STATE_CODES", "actuate", "actuate_boats", "add_terms",
           "with_terms"]
