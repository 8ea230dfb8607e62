"""The sensor chain's arithmetic, written once on one boat's channels and compiled: what the
environments' step kernel runs for every boat and what each sensor stage of
:mod:`marine_envs.sensors` runs alone (a stage keeps its configuration and its state; the chain
here computes). The stages, in the order of :meth:`~marine_envs.sensors.SensorSuite.standard`::

    bias -> Gaussian noise -> angle wrapping -> quantizer (static or zooming) -> saturation
    -> sample and hold -> delay -> dropout (hold)
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import jit

#: Zooming laws, as :func:`measure_chain` reads them.
RELATIVE, ZOOM = 0, 1


@jit(inline="never")  # once per measurement: compiled once, not into every caller
def measure_chain(boats, z, bias, wrap, mu, group, zoom_settings, limit, period, lag, prob,
                  noisy, zooming, holding, delaying, dropping,
                  noise_rows, noise_cursor, zoom_mu, count, held, buf, head, delay_fresh,
                  dropout_rows, dropout_cursor, kept, dropout_fresh, y, valid):
    """The standard chain (:meth:`~marine_envs.sensors.SensorSuite.standard`, module docstring)
    of boats ``boats`` (row r of the true values ``z`` is boat ``boats[r]``'s), boat by boat:
    measurements to ``y``, fresh samples to ``valid`` (rows as ``z``); only those boats' sensors
    advance. Row ``cursor[b]`` of a random stream is boat b's current draw; the cursors advance
    by one. A stage is on where its flag (``noisy`` ...) says so or its setting is not neutral
    (bias 0, no wrap, step NaN, limit inf, period 1)."""
    m = z.shape[1]
    for r in range(boats.size):
        b = boats[r]
        row = y[r]
        for c in range(m):
            a = z[r, c] + bias[c]
            if noisy:
                a += noise_rows[noise_cursor[b], c]
            if wrap[c]:  # pi - ((pi - a) mod 2 pi) lies in (-pi, pi]
                a = math.pi - (math.pi - a) % (2 * math.pi)
            if not np.isnan(mu[c]):
                a = mu[c] * np.rint(a / mu[c])
            row[c] = a
        if zooming:
            _zoom(row, group, zoom_settings, zoom_mu[b])
        for c in range(m):
            a = row[c]
            if a < -limit[c]:
                a = -limit[c]
            elif a > limit[c]:
                a = limit[c]
            fresh = True
            if holding:
                fresh = count[b] % period[c] == 0
                if fresh:
                    held[b, c] = a
                a = held[b, c]
            row[c] = a
            valid[r, c] = fresh
        if holding:
            count[b] += 1
        if noisy:
            noise_cursor[b] += 1
        if delaying:
            length = buf.shape[1]
            head[b] = (head[b] + 1) % length
            for c in range(m):
                if delay_fresh[b]:  # the line starts full of the first measurement
                    for slot in range(length):
                        buf[b, slot, c] = row[c]
                buf[b, head[b], c] = row[c]
            delay_fresh[b] = False
            for c in range(m):
                row[c] = buf[b, (head[b] - lag[c]) % length, c]
        if dropping:
            for c in range(m):
                arrived = dropout_rows[dropout_cursor[b], c] >= prob[c] or dropout_fresh[b]
                if arrived:
                    kept[b, c] = row[c]
                row[c] = kept[b, c]
                valid[r, c] = valid[r, c] and arrived
            dropout_fresh[b] = False
            dropout_cursor[b] += 1


@jit
def _zoom(row, group, settings, mu):
    """The zooming quantizer (:class:`~marine_envs.sensors.ZoomingQuantizer`) on one boat's
    channels ``row``, in
    place; ``mu`` is the boat's zoom variable per group (updated)."""
    law, k, levels, zoom_in, margin = settings[0], settings[1], settings[2], settings[3], \
        settings[4]
    for g in range(mu.size):
        size, norm, peak, index_peak = 0, 0.0, 0.0, 0.0
        for c in range(row.size):
            if group[c] == g:
                size += 1
                norm += row[c] * row[c]
                peak = max(peak, abs(row[c]))
                if law == ZOOM:
                    index_peak = max(index_peak, abs(np.rint(row[c] / mu[g])))
        norm = math.sqrt(norm)
        if law == RELATIVE:
            step = 2 * k * norm / math.sqrt(size)
            mu[g] = step
            usable = step > 1e-12 * (1 + norm)
            for c in range(row.size):
                if group[c] == g:
                    row[c] = step * np.rint(row[c] / step) if usable else 0.0
        else:
            step = mu[g]
            for c in range(row.size):
                if group[c] == g:
                    row[c] = step * min(max(np.rint(row[c] / step), -levels), levels)
            if index_peak > levels:
                mu[g] = step / zoom_in
            elif peak <= margin * levels * step:
                mu[g] = step * zoom_in


__all__ = ["RELATIVE", "ZOOM", "measure_chain"]
