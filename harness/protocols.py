"""The objects plugins build, as ``typing.Protocol`` classes.

A spec's ``factory`` returns one of these. The optional parts are protocols of their own and are
declared in the spec, so the harness never guesses with ``hasattr``:

============================  ======================================  ==========================
protocol                      what                                    declared by
============================  ======================================  ==========================
:class:`Filter`               ``reset()``, ``__call__(frame, sampler)`` every ``FilterSpec``
:class:`StageTimedFilter`     ``stage_ms`` after each call            ``FilterSpec.stage_timing``
:class:`Renderer`             ``settings``, ``render``, ``reference``  every ``RendererSpec``
:class:`ChunkedRenderer`      ``accumulate`` (a range of samples)     ``RendererSpec.chunked``
:class:`AdaptiveRenderer`     ``sampler`` (more samples on demand)    ``RendererSpec.adaptive``
:class:`KnownNoiseRenderer`   ``reference_variance`` (stored noise)   ``RendererSpec.reference_noise``
:class:`Metric`               ``__call__(output(s), reference(s))``   every ``MetricSpec``
============================  ======================================  ==========================

:func:`check_renderer` verifies that a built renderer has what its spec declares.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from harness.buffers import Frame
from harness.sampling import Sampler


@runtime_checkable
class Filter(Protocol):
    """A reconstruction filter: ``spec.factory(backend="cpu", **params)`` returns one."""

    def reset(self) -> None:
        """Forget any history (a new sequence or a camera cut)."""

    def __call__(self, frame: Frame, sampler: Sampler | None = None) -> np.ndarray:
        """Filter one frame; returns (H, W, 3) float32, finite where the input is finite."""


@runtime_checkable
class StageTimedFilter(Filter, Protocol):
    """A filter that reports the milliseconds of its stages (``FilterSpec.stage_timing``)."""

    stage_ms: Mapping[str, float]


@runtime_checkable
class Renderer(Protocol):
    """A renderer: ``spec.factory(**settings)`` returns one."""

    def settings(self) -> dict:
        """Every setting that changes its output (part of every cache key)."""

    def render(
        self, scene: Any, frame_index: int, *, spp: int, seed: int, channels: frozenset, resolution: tuple
    ) -> Frame:
        """The noisy frame with ``color`` and the requested channels, nothing more."""

    def reference(self, scene: Any, frame_index: int, *, spp: int, seed: int, resolution: tuple) -> np.ndarray:
        """The converged image (H, W, 3) float32."""


@runtime_checkable
class ChunkedRenderer(Renderer, Protocol):
    """A renderer whose references are sums of sample ranges (``RendererSpec.chunked``)."""

    def accumulate(
        self, scene: Any, frame_index: int, *, first_sample: int, count: int, seed: int, resolution: tuple
    ) -> np.ndarray:
        """The float64 (H, W, 3) sum of samples ``first_sample .. first_sample + count - 1``.

        The sums of consecutive ranges added in order, divided by the total count, give the
        reference of that many samples, whatever the chunking.
        """


@runtime_checkable
class KnownNoiseRenderer(Renderer, Protocol):
    """A renderer whose references state their own noise (``RendererSpec.reference_noise``)."""

    def reference_variance(self, scene: Any, frame_index: int) -> np.ndarray | None:
        """The (H, W, 3) per-pixel variance of the mean of ``reference``, or None if unknown."""


@runtime_checkable
class AdaptiveRenderer(Renderer, Protocol):
    """A renderer serving adaptive filters (``RendererSpec.adaptive``)."""

    def sampler(
        self, scene: Any, frame_index: int, *, spp: int, seed: int, channels: frozenset, resolution: tuple
    ) -> Sampler:
        """A :class:`harness.Sampler` starting from the frame ``render`` would give."""


@runtime_checkable
class Metric(Protocol):
    """A metric: ``spec.factory()`` returns one.

    ``kind="frame"``: ``metric(output, reference) -> float`` on (H, W, 3) float32 linear images;
    ``kind="sequence"``: ``metric(outputs, references) -> float`` on lists of them. A metric
    whose spec declares ``accepts`` also receives those keyword arguments
    (``reference_variance=``, ``mask=``; see :class:`harness.MetricSpec`).
    """

    def __call__(self, output: np.ndarray | Sequence[np.ndarray], reference: Any, **inputs: Any) -> float: ...


def check_renderer(spec, renderer) -> None:
    """Raise ``TypeError`` naming the plugin when ``renderer`` lacks a part its spec declares."""
    wanted = [(Renderer, "settings/render/reference")]
    if spec.chunked:
        wanted.append((ChunkedRenderer, "accumulate (declared chunked=True)"))
    if spec.adaptive:
        wanted.append((AdaptiveRenderer, "sampler (declared adaptive=True)"))
    if spec.reference_noise:
        wanted.append((KnownNoiseRenderer, "reference_variance (declared reference_noise=True)"))
    for protocol, what in wanted:
        if not isinstance(renderer, protocol):
            raise TypeError(f"renderer {spec.name!r}: {type(renderer).__name__} lacks {what}")
