"""Sensors: what the vehicle's instruments make of its true state.

A :class:`SensorSuite` maps true channel values ``z`` (batch x channels, SI units) to measurements
through a chain of small stages, each configured per channel and vectorised over the batch::

    bias -> Gaussian noise -> angle wrapping -> quantizer -> saturation
    -> sample and hold (sensors slower than the control loop) -> delay -> dropout (hold)

Every stage works on a batch of independent sensor suites (one per boat of a vector environment).
A standard stage keeps its configuration and its per-boat state; its arithmetic is the compiled
chain's (:func:`~marine_envs.sensor_chain.measure_chain`, with that stage alone), the very code
the environments' step kernel runs for the whole chain.
Randomness comes from each boat's own ``np.random.Generator`` (handed down from
``reset(seed=...)``) and is drawn in blocks, so a batch of boats consumes exactly the random
streams that the same boats would consume one by one: a batched environment equals N single ones.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .blocks import BLOCK, BlockStream
from .sensor_chain import RELATIVE, ZOOM, measure_chain

FloatArray = NDArray[np.float64]


def per_channel(name: str, value: float | Mapping[str, float] | None, channels: Sequence[str],
                default: float = 0.0) -> FloatArray:
    """Expand a scalar or a ``{channel: value}`` mapping to one value per channel.

    None, for every channel or as a channel's value, and a channel the mapping does not name
    give ``default`` (for a sensor setting: that stage off on the channel).

    :raises ValueError: a channel name that is not one of ``channels``, naming the argument.
    """
    if value is None:
        return np.full(len(channels), default, dtype=float)
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - set(channels))
        if unknown:
            raise ValueError(f"{name}: unknown channel(s) {unknown}; channels are "
                             f"{', '.join(channels)}")
        return np.array([default if value.get(c) is None else float(value[c]) for c in channels])
    return np.full(len(channels), float(value))


class Stage(ABC):
    """One step of the measurement chain. :meth:`__call__` may overwrite its input array (the
    suite owns it) and returns the stage's output."""

    def bind(self, batch_size: int) -> None:  # noqa: B027 - stateless stages keep this default
        """Allocate per-boat state for ``batch_size`` boats."""

    def reset(self, idx: NDArray[np.intp],  # noqa: B027 - stateless stages keep this default
              rngs: Sequence[np.random.Generator]) -> None:
        """Start new episodes for boats ``idx`` (``rngs[i]`` is boat ``idx[i]``'s generator)."""

    @abstractmethod
    def __call__(self, z: FloatArray) -> FloatArray:
        """Measurements of ``z`` (batch x channels)."""


def as_index(idx: NDArray[np.intp]) -> slice | NDArray[np.intp]:
    """A slice when the indices are contiguous (basic indexing is much cheaper than fancy)."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


class _ChainStage(Stage):
    """A stage of the standard chain: its configuration and state here, its arithmetic the
    compiled chain's with this stage alone (made for the batch and width at the first call
    after :meth:`bind`). After each call :attr:`valid` tells which channels carry a fresh
    sample (all, but for sample-and-hold and dropout)."""

    _chain: CompiledChain | None = None

    def bind(self, batch_size: int) -> None:
        self._chain = None

    def __call__(self, z: FloatArray) -> FloatArray:
        chain = self._chain
        if chain is None or chain.valid.shape != z.shape:
            chain = self._chain = CompiledChain(SensorSuite(tuple(map(str, range(z.shape[1]))),
                                                            [self]))
            chain.bind(z.shape[0])
        y, self.valid = chain.measure(z)
        return y


class _RandomStage(_ChainStage):
    """A stage driven by per-boat random numbers, drawn a block at a time from each boat's
    generator so that a boat's draws never depend on the other boats of the batch."""

    def __init__(self, width: int) -> None:
        #: The rows, a block at a time per boat (read by the compiled step kernel too).
        self.stream = BlockStream(width, self._draw_blocks)

    @abstractmethod
    def _draw(self, rng: np.random.Generator, out: FloatArray) -> None:
        """One boat's next block of random numbers into ``out`` (BLOCK x width)."""

    def _draw_blocks(self, idx: NDArray[np.intp]) -> FloatArray:
        blocks = np.empty((idx.size, BLOCK, self.stream.width))
        for block, i in zip(blocks, idx, strict=True):  # into place: no copy per boat
            self._draw(self._rngs[i], block)
        return blocks

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.stream.bind(batch_size)
        self._rngs: list[np.random.Generator] = [np.random.default_rng(0)] * batch_size

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        for i, rng in zip(idx, rngs, strict=True):
            self._rngs[i] = rng
        self.stream.restart(idx)


class Bias(_ChainStage):
    """Constant additive bias per channel (channel units)."""

    def __init__(self, bias: ArrayLike) -> None:
        self.bias = np.asarray(bias, dtype=float)


class GaussianNoise(_RandomStage):
    """Additive white Gaussian noise with standard deviation ``std`` per channel."""

    def __init__(self, std: ArrayLike) -> None:
        self.std = np.asarray(std, dtype=float)
        if not np.all(np.isfinite(self.std) & (self.std >= 0)):
            raise ValueError(f"noise std={self.std.tolist()} is invalid: must be finite and >= 0")
        super().__init__(self.std.size)

    def _draw(self, rng: np.random.Generator, out: FloatArray) -> None:
        rng.standard_normal(out=out)
        out *= self.std  # scaled as drawn, so a step costs one addition


class WrapAngle(_ChainStage):
    """Wrap the selected channels to ``(-pi, pi]`` (a compass reads heading modulo a turn)."""

    def __init__(self, mask: ArrayLike) -> None:
        self.idx = as_index(np.flatnonzero(np.asarray(mask, dtype=bool)))


def quantize(z: ArrayLike, mu: ArrayLike) -> FloatArray:
    """Uniform quantizer ``mu * round(z / mu)``; its error is at most ``mu / 2`` per component."""
    return mu * np.rint(np.divide(z, mu))


class Quantizer(_ChainStage):
    """Static uniform quantizer ``mu*round(z/mu)`` on the channels whose step ``mu`` is not NaN."""

    def __init__(self, step: ArrayLike) -> None:
        step = np.asarray(step, dtype=float)
        active = ~np.isnan(step)
        if not np.all(step[active] > 0) or not np.all(np.isfinite(step[active])):
            raise ValueError(f"quantization step={step.tolist()} is invalid: must be finite and "
                             "> 0 (use None for an unquantized channel)")
        # mu shaped (1, channels): equal-rank operands broadcast faster
        self.idx, self.mu = as_index(np.flatnonzero(active)), step[active][None, :]


class ZoomingQuantizer(_ChainStage):
    """Dynamic ("zooming") uniform quantizer of the USV observer patent, one zoom variable per
    channel group.

    ``law="relative"`` (the patent's, docs/models.md 1.4): ``mu = 2 k ||z|| / sqrt(m)`` for a
    group of ``m`` channels, so ``||q(z) - z|| <= k ||z||`` with ``0 < k < 1``: the quantizer
    zooms in as the signal shrinks. ``mu`` must reach the receiver as side information.

    ``law="zoom"`` (Brockett-Liberzon): piecewise-constant ``mu`` on ``2 levels + 1`` levels;
    ``mu`` is multiplied by ``zoom_in`` (< 1) while the signal stays within ``margin`` of the range
    and divided by it when the quantizer saturates. Error ``<= mu/2`` when not saturated.
    """

    def __init__(self, groups: Sequence[Sequence[int]], k: float = 0.6,
                 law: Literal["relative", "zoom"] = "relative", mu0: float = 1.0,
                 levels: int = 16, zoom_in: float = 0.8, margin: float = 0.5) -> None:
        if not 0 < k < 1:
            raise ValueError(f"k={k!r} is invalid: the zoom rate must be in (0, 1)")
        if law not in ("relative", "zoom"):
            raise ValueError(f"law={law!r} is invalid: 'relative' or 'zoom'")
        if not (mu0 > 0 and levels >= 1 and 0 < zoom_in < 1 and 0 < margin < 1):
            raise ValueError("zooming quantizer needs mu0 > 0, levels >= 1, 0 < zoom_in < 1 "
                             f"and 0 < margin < 1 (got {mu0}, {levels}, {zoom_in}, {margin})")
        self.groups = [np.asarray(g, dtype=np.intp) for g in groups]
        self.k, self.law, self.mu0 = k, law, mu0
        self.levels, self.zoom_in, self.margin = levels, zoom_in, margin

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        #: Current zoom variable per boat and group (the side information to transmit).
        self.mu = np.full((batch_size, len(self.groups)), self.mu0)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        self.mu[idx] = self.mu0


class Saturation(_ChainStage):
    """Full-scale range of each channel: outputs are clamped to ``[-limit, limit]``."""

    def __init__(self, limit: ArrayLike) -> None:
        limit = np.asarray(limit, dtype=float)
        if not np.all(limit > 0):
            raise ValueError(f"range={limit.tolist()} is invalid: full scales must be > 0")
        self.high, self.low = limit[None, :], -limit[None, :]


class Delay(_ChainStage):
    """Transport delay of a whole number of samples per channel (0 = none).

    Right after a reset the delayed channels repeat the first measurement.
    """

    def __init__(self, samples: ArrayLike) -> None:
        samples = np.asarray(samples)
        if not (np.all(samples >= 0) and np.all(samples == np.round(samples))):
            raise ValueError(f"delay={samples.tolist()} is invalid: whole samples >= 0 needed")
        self.samples = samples.astype(np.intp)
        self.length = int(self.samples.max()) + 1

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.buf = np.zeros((batch_size, self.length, self.samples.size))
        #: each boat's slot written last (per boat: a boat may be measured alone)
        self.head = np.zeros(batch_size, dtype=np.int64)
        self.fresh = np.ones(batch_size, dtype=bool)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        self.fresh[idx] = True


class SampleHold(_ChainStage):
    """A sensor slower than the control loop: channel c is sampled every ``period[c]`` control
    steps (from the first step of an episode) and held in between.

    After each call :attr:`valid` tells which channels carry a fresh sample (for estimators).
    """

    def __init__(self, period: ArrayLike) -> None:
        period = np.asarray(period)
        if not (np.all(period >= 1) and np.all(period == np.round(period))):
            raise ValueError(f"sample_period={period.tolist()} is invalid: whole control steps "
                             ">= 1 needed")
        self.period = period.astype(np.int64)[None, :]

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.count = np.zeros((batch_size, 1), dtype=np.int64)
        self.last = np.zeros((batch_size, self.period.size))
        self.valid = np.ones((batch_size, self.period.size), dtype=bool)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        self.count[idx] = 0


class Dropout(_RandomStage):
    """Each sample of a channel is lost with probability ``prob``; the last value is held.

    After each call :attr:`valid` tells which channels carry a fresh sample (for estimators).
    """

    def __init__(self, prob: ArrayLike) -> None:
        self.prob = np.asarray(prob, dtype=float)
        if not np.all((self.prob >= 0) & (self.prob < 1)):
            raise ValueError(f"dropout={self.prob.tolist()} is invalid: probabilities in [0, 1)")
        super().__init__(self.prob.size)

    def _draw(self, rng: np.random.Generator, out: FloatArray) -> None:
        rng.random(out=out)

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.last = np.zeros((batch_size, self.prob.size))
        self.fresh = np.ones(batch_size, dtype=bool)
        self.valid = np.ones((batch_size, self.prob.size), dtype=bool)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        super().reset(idx, rngs)
        self.fresh[idx] = True  # the first sample of an episode always arrives


class SensorSuite:
    """A chain of sensor stages over named channels, batched over boats.

    :param channels: names of the measured channels (model state names).
    :param stages: the chain, applied in order.
    """

    def __init__(self, channels: Sequence[str], stages: Sequence[Stage]) -> None:
        self.channels = tuple(channels)
        self.stages = list(stages)
        self._masking = [s for s in self.stages if isinstance(s, SampleHold | Dropout)]

    @classmethod
    def standard(cls, channels: Sequence[str], *, noise_std=None, bias=None, quantization=None,
                 sensor_range=None, sample_period=None, delay=None, dropout=None,
                 wrap: Sequence[str] = (),
                 quantizer: Literal["static", "zooming"] = "static",
                 zoom_k: float = 0.6) -> SensorSuite:
        """The usual chain from per-channel settings (scalars or ``{channel: value}``).

        Stages whose settings are all zero/None are left out, so they cost nothing.
        ``sample_period`` gives each sensor's period in control steps (1 = every step).
        ``quantization`` gives the static step per channel (channel units), ``sensor_range`` the
        full scale (outputs clamped to +-range; wrapped angles need none); with
        ``quantizer="zooming"`` it selects the channels quantized by the USV observer patent's
        zooming law.
        """
        stages: list[Stage] = []
        b = per_channel("bias", bias, channels)
        if np.any(b != 0):
            stages.append(Bias(b))
        std = per_channel("noise_std", noise_std, channels)
        if np.any(std != 0):
            stages.append(GaussianNoise(std))
        unknown = sorted(set(wrap) - set(channels))
        if unknown:
            raise ValueError(f"wrap: unknown channel(s) {unknown}")
        if wrap:
            stages.append(WrapAngle([c in wrap for c in channels]))
        mu = per_channel("quantization", quantization, channels, default=math.nan)
        if not np.all(np.isnan(mu)):
            if quantizer == "static":
                stages.append(Quantizer(mu))
            elif quantizer == "zooming":
                stages.append(ZoomingQuantizer([[i] for i in np.flatnonzero(~np.isnan(mu))],
                                               k=zoom_k))
            else:
                raise ValueError(f"quantizer={quantizer!r} is invalid: 'static' or 'zooming'")
        full_scale = per_channel("sensor_range", sensor_range, channels, default=math.inf)
        if np.isfinite(full_scale).any():
            stages.append(Saturation(full_scale))
        period = per_channel("sample_period", sample_period, channels, default=1)
        if np.any(period != 1):
            stages.append(SampleHold(period))
        lag = per_channel("delay", delay, channels)
        if np.any(lag != 0):
            stages.append(Delay(lag))
        p = per_channel("dropout", dropout, channels)
        if np.any(p != 0):
            stages.append(Dropout(p))
        return cls(channels, stages)

    def bind(self, batch_size: int) -> None:
        """Allocate state for ``batch_size`` boats."""
        self._all_valid = np.ones((batch_size, len(self.channels)), dtype=bool)
        self._all_valid.flags.writeable = False
        for stage in self.stages:
            stage.bind(batch_size)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        """Start new episodes for boats ``idx``, drawing from their generators ``rngs``."""
        for stage in self.stages:
            stage.reset(idx, rngs)

    def measure(self, z: FloatArray) -> FloatArray:
        """Measurements (batch x channels) of the true channel values ``z`` (overwritten)."""
        for stage in self.stages:
            z = stage(z)
        return z

    @property
    def output_range(self) -> FloatArray:
        """Largest possible magnitude of each channel's output (inf where unbounded)."""
        bound = np.full(len(self.channels), math.inf)
        for stage in self.stages:
            if isinstance(stage, WrapAngle):
                bound[stage.idx] = math.pi
            elif isinstance(stage, Quantizer):
                bound[stage.idx] += stage.mu[0] / 2  # rounding may step past the bound
            elif isinstance(stage, ZoomingQuantizer):
                bound *= 1 + stage.k
            elif isinstance(stage, Saturation):
                bound = np.minimum(bound, stage.high[0])
            elif isinstance(stage, Bias | GaussianNoise):
                bound[:] = math.inf
        return bound

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Which channels carried a fresh sample at the last :meth:`measure` (False = held)."""
        if not self._masking:
            return self._all_valid
        if len(self._masking) == 1:
            return self._masking[0].valid
        return self._masking[0].valid & self._masking[1].valid


# -- the standard chain, compiled ------------------------------------------------------------------
#: The stage types :func:`measure_chain` runs, in the order of :meth:`SensorSuite.standard`.
CHAIN_ORDER = (Bias, GaussianNoise, WrapAngle, (Quantizer, ZoomingQuantizer), Saturation,
               SampleHold, Delay, Dropout)
STANDARD = (Bias, GaussianNoise, WrapAngle, Quantizer, ZoomingQuantizer, Saturation, SampleHold,
            Delay, Dropout)


class CompiledChain:
    """A :class:`SensorSuite` of the standard stages (:data:`CHAIN_ORDER`) run by the compiled
    :func:`measure_chain`: the same measurements, the same random streams, the state kept in the
    stages themselves. :meth:`of` returns None for a chain it cannot run (a stage of another
    kind, or stages out of order), which then runs stage by stage in numpy.
    """

    def __init__(self, suite: SensorSuite) -> None:
        m = len(suite.channels)
        # by standard kind: a stage of a subclass measures as its kind (run alone, as a stage)
        found = {kind: s for s in suite.stages for kind in STANDARD if isinstance(s, kind)}
        self.suite = suite
        self.bias = found[Bias].bias.copy() if Bias in found else np.zeros(m)
        self.noise = found.get(GaussianNoise)
        self.wrap = np.zeros(m, dtype=np.bool_)
        if WrapAngle in found:
            self.wrap[found[WrapAngle].idx] = True
        self.mu = np.full(m, np.nan)
        if Quantizer in found:
            self.mu[found[Quantizer].idx] = found[Quantizer].mu[0]
        self.zoom = found.get(ZoomingQuantizer)
        self.group = np.full(m, -1, dtype=np.int64)  # each channel's zoom group (-1: none)
        if self.zoom is not None:
            for g, channels in enumerate(self.zoom.groups):
                self.group[channels] = g
            z = self.zoom
            self.zoom_settings = np.array([RELATIVE if z.law == "relative" else ZOOM, z.k,
                                           z.levels, z.zoom_in, z.margin])
        else:
            self.zoom_settings = np.zeros(5)
        self.limit = found[Saturation].high[0].copy() if Saturation in found else np.full(m, np.inf)
        self.hold = found.get(SampleHold)
        self.period = self.hold.period[0].copy() if self.hold else np.ones(m, dtype=np.int64)
        self.delay = found.get(Delay)
        self.lag = self.delay.samples.astype(np.int64) if self.delay else np.zeros(m, np.int64)
        self.dropout = found.get(Dropout)
        self.prob = self.dropout.prob.copy() if self.dropout else np.zeros(m)

    @classmethod
    def of(cls, suite: SensorSuite) -> CompiledChain | None:
        """The compiled twin of ``suite``, or None when its stages are not the standard ones in
        the standard order."""
        ranks = []
        for stage in suite.stages:
            rank = next((i for i, kind in enumerate(CHAIN_ORDER) if type(stage) in
                         (kind if isinstance(kind, tuple) else (kind,))), None)
            if rank is None:
                return None
            ranks.append(rank)
        if ranks != sorted(set(ranks)):
            return None
        return cls(suite)

    def bind(self, batch_size: int) -> None:
        """Per-boat state the stages do not keep (the suite itself is bound by its owner)."""
        #: Which channels carried a fresh sample at the last measurement (False = held).
        self.valid = np.ones((batch_size, len(self.suite.channels)), dtype=np.bool_)
        self._none2 = np.zeros((batch_size, 0))
        self._none_i = np.zeros(batch_size, dtype=np.int64)
        self._none_b = np.zeros(batch_size, dtype=np.bool_)
        self._none3 = np.zeros((batch_size, 1, 0))
        self.boats = np.arange(batch_size, dtype=np.int64)  # every boat, for measure_chain

    def begin(self) -> tuple:
        """Start a measurement: the arrays :func:`measure_chain` reads and updates, after the
        configuration (gathered anew: the stages own them). Call :meth:`end` after it ran."""
        empty2, empty_i, empty_b = self._none2, self._none_i, self._none_b
        noise = self.noise.stream if self.noise is not None else None
        dropout = self.dropout.stream if self.dropout is not None else None
        return (
            noise.rows if noise else empty2, noise.cursor if noise else empty_i,
            self.zoom.mu if self.zoom else empty2,
            self.hold.count[:, 0] if self.hold else empty_i,
            self.hold.last if self.hold else empty2,
            self.delay.buf if self.delay else self._none3,
            self.delay.head if self.delay else empty_i,
            self.delay.fresh if self.delay else empty_b,
            dropout.rows if dropout else empty2, dropout.cursor if dropout else empty_i,
            self.dropout.last if self.dropout else empty2,
            self.dropout.fresh if self.dropout else empty_b)

    def configuration(self) -> tuple:
        """The constant arrays :func:`measure_chain` reads, and the stages present."""
        return (self.bias, self.wrap, self.mu, self.group, self.zoom_settings, self.limit,
                self.period, self.lag, self.prob, self.noise is not None, self.zoom is not None,
                self.hold is not None, self.delay is not None, self.dropout is not None)

    def end(self) -> None:
        """End a measurement: account for the rows :func:`measure_chain` took from the random
        streams."""
        for stage in (self.noise, self.dropout):
            if stage is not None:
                stage.stream.advanced()

    def measure(self, z: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Measurements and valid channels (batch x channels) of true values ``z``."""
        y = np.empty_like(z)
        valid = np.empty(z.shape, dtype=np.bool_)
        measure_chain(self.boats, np.ascontiguousarray(z, dtype=float), *self.configuration(),
                      *self.begin(), y, valid)
        self.end()
        self.valid = valid
        return y, valid
