"""Random numbers per sample: one PCG32 stream for each (seed, frame, purpose, sample index, pixel).

Mitsuba's own samplers number their streams by the position of a lane in the wavefront, so the
same sample would get other numbers when it is rendered in another batch. Here a Python
:class:`mitsuba.Sampler` gives lane ``l`` the PCG32 stream seeded from the key of its sample:

    key = mix64(base(seed, frame, purpose) ^ (sample << 32 | pixel)),
    state, sequence = key, mix64(~key),

with ``mix64`` the SplitMix64 finaliser (a bijection of 64-bit integers) and ``base`` the same
finaliser over the seed, frame and purpose. A sample's path is therefore the same bit for bit
whatever range, batch, order or process renders it: chunked references, resumed references and
adaptive samples that continue a pixel's stream all see the same numbers, and two seeds, two
frames or two purposes (noisy samples, the independent set of the variance channel) share
none. The integrator calls ``next_1d``/``next_2d`` while it traces, so the streams cost no
Python work per lane.
"""

from __future__ import annotations

MASK64 = (1 << 64) - 1
#: purposes of sample streams
COLOR, VARIANCE = 1, 2
_GOLDEN = 0x9E3779B97F4A7C15
_M1, _M2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB

_CLASSES: dict = {}


def mix64(x: int) -> int:
    """SplitMix64's finaliser on a Python int (mod 2^64)."""
    x = (x + _GOLDEN) & MASK64
    x = ((x ^ (x >> 30)) * _M1) & MASK64
    x = ((x ^ (x >> 27)) * _M2) & MASK64
    return x ^ (x >> 31)


def base_key(seed: int, frame: int, purpose: int) -> int:
    """The 64-bit key of every stream of (seed, frame, purpose)."""
    return mix64(mix64(mix64(int(purpose)) ^ (int(seed) & MASK64)) ^ (int(frame) & MASK64))


def _mix64_jit(mi, x):
    x = x + mi.UInt64(_GOLDEN)
    x = (x ^ (x >> 30)) * mi.UInt64(_M1)
    x = (x ^ (x >> 27)) * mi.UInt64(_M2)
    return x ^ (x >> 31)


def lane_keys(mi, base: int, pixels, samples):
    """(state, sequence) UInt64 arrays seeding each lane's stream (JIT variants).

    Parameters
    ----------
    mi : module
        ``mitsuba`` with a JIT variant set.
    base : int
        :func:`base_key`.
    pixels, samples : mitsuba.UInt32
        Row-major pixel index and sample index of each lane.
    """
    import drjit as dr

    # opaque: a literal would be compiled into the kernel, one compilation per seed and frame
    key = _mix64_jit(mi, dr.opaque(mi.UInt64, base) ^ ((mi.UInt64(samples) << 32) | mi.UInt64(pixels)))
    return key, _mix64_jit(mi, ~key)


def image_seed(base: int, sample: int) -> int:
    """The 32-bit ``seed`` of ``mi.render`` for one sample index of every pixel (scalar variant)."""
    return mix64(base ^ ((int(sample) & 0xFFFFFFFF) << 32)) & 0xFFFFFFFF


def stream_sampler(mi):
    """A new sampler of the current (JIT) variant whose lanes follow :func:`lane_keys` streams.

    Call ``sampler.start(state, sequence)`` before each wavefront.
    """
    variant = mi.variant()
    cls = _CLASSES.get(variant)
    if cls is None:
        class StreamSampler(mi.Sampler):
            """PCG32 per lane, seeded per sample (not per wavefront position)."""

            def __init__(self):
                super().__init__(mi.Properties())
                self.rng = mi.PCG32()

            def start(self, state, sequence):
                self.rng = mi.PCG32()
                self.rng.seed(state, sequence)

            def next_1d(self, active=True):
                return self.rng.next_float32(active)

            def next_2d(self, active=True):
                u = self.rng.next_float32(active)
                v = self.rng.next_float32(active)
                return mi.Point2f(u, v)

        cls = _CLASSES[variant] = StreamSampler
    return cls()
