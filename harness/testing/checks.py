"""Conformance checks that every plugin of a kind must pass.

Each check is a function ``check(spec, backend)`` that raises ``AssertionError`` with a message
naming the plugin when the plugin misbehaves. :func:`parametrize_with_checks` turns them into
pytest parameters; :data:`FILTER_CHECKS` and friends list them by name.
"""

from __future__ import annotations

import copy

import numpy as np

from harness.buffers import Frame, check_filter_output
from harness.stress.frames import with_color
from harness.testing.frames import make_frame

SIZES = [(1, 1), (1, 7), (6, 1), (7, 5), (16, 12)]


def _filter(spec, backend):
    f = spec.factory(backend=backend, **dict(spec.params))
    f.reset()
    return f


def _frame(spec, **kw) -> Frame:
    return make_frame(channels=spec.requires | spec.optional, **kw)


def _run(spec, backend, frames) -> list[np.ndarray]:
    f = _filter(spec, backend)
    outs = []
    for frame in frames:
        out = f(frame, sampler=None)
        check_filter_output(out, frame, owner=f"filter {spec.name!r}")
        outs.append(np.array(out, copy=True))
    return outs


def _sequence(spec, **kw) -> list[Frame]:
    n = 3 if spec.temporal else 1
    return [_frame(spec, index=t, **kw) for t in range(n)]


def check_output_shape_dtype(spec, backend):
    """The output is an (H, W, 3) float32 array of finite values."""
    _run(spec, backend, _sequence(spec))


def check_input_not_modified(spec, backend):
    """The filter leaves its input frame as it was."""
    frames = _sequence(spec)
    before = [{n: f[n].copy() for n in f.channels} for f in frames]
    _run(spec, backend, frames)
    for b, f in zip(before, frames):
        for name, array in b.items():
            assert np.array_equal(array, f[name], equal_nan=True), (
                f"filter {spec.name!r} modified input channel {name!r}"
            )


def check_deterministic(spec, backend):
    """Two fresh instances give bit-identical outputs on the same input."""
    a = _run(spec, backend, _sequence(spec))
    b = _run(spec, backend, _sequence(spec))
    for t, (x, y) in enumerate(zip(a, b)):
        assert np.array_equal(x, y), (
            f"filter {spec.name!r} is not deterministic (frame {t}, max diff {np.abs(x - y).max()})"
        )


def check_constant_image(spec, backend):
    """A constant image over constant features stays constant."""
    value = np.array([0.25, 0.5, 0.75], np.float32)
    outs = _run(spec, backend, _sequence(spec, color=value, constant_features=True))
    for t, out in enumerate(outs):
        err = np.abs(out - value).max()
        assert err <= 1e-4 * 0.75 + 1e-6, f"filter {spec.name!r} changed a constant image by {err} (frame {t})"


def check_zero_image(spec, backend):
    """All-zero colour in gives all-zero colour out."""
    outs = _run(spec, backend, _sequence(spec, color=0.0))
    for t, out in enumerate(outs):
        assert np.abs(out).max() <= 1e-12, (
            f"filter {spec.name!r} made {np.abs(out).max()} out of a zero image (frame {t})"
        )


def _extreme(spec, backend, make_color, label):
    frames = []
    for t in range(3 if spec.temporal else 1):
        base = _frame(spec, index=t)
        color = make_color(base["color"].copy(), np.random.default_rng(t))
        frames.append(with_color(base, color.astype(np.float32)))  # direct/indirect follow the colour
    outs = _run(spec, backend, frames)  # check_filter_output rejects non-finite output
    for out in outs:
        assert np.isfinite(out).all(), f"filter {spec.name!r}: non-finite output for {label} input"


def check_fireflies(spec, backend):
    """Isolated 1e6 fireflies give finite output."""

    def fire(c, rng):
        idx = rng.integers(0, c.shape[0] * c.shape[1], size=max(1, c.size // 60))
        c.reshape(-1, 3)[idx] = 1e6
        return c

    _extreme(spec, backend, fire, "firefly (1e6)")


def check_huge_values(spec, backend):
    """Values of 1e30 give finite output."""
    _extreme(spec, backend, lambda c, rng: c * np.float32(1e30), "huge (1e30)")


def check_tiny_values(spec, backend):
    """Values of 1e-30 give finite output."""
    _extreme(spec, backend, lambda c, rng: c * np.float32(1e-30), "tiny (1e-30)")


def check_float16_range(spec, backend):
    """Values spanning the float16 range (6e-8 .. 65504) give finite output."""

    def span(c, rng):
        return np.exp(rng.uniform(np.log(6e-8), np.log(65504.0), size=c.shape)).astype(np.float32)

    _extreme(spec, backend, span, "float16-range")


def check_sizes(spec, backend):
    """1x1, 1xN, Nx1 and odd sizes work."""
    for h, w in SIZES:
        frames = [make_frame(h, w, spec.requires | spec.optional, index=t) for t in range(2 if spec.temporal else 1)]
        try:
            _run(spec, backend, frames)
        except Exception as exc:
            raise AssertionError(
                f"filter {spec.name!r} failed on a {h}x{w} image: {type(exc).__name__}: {exc}"
            ) from exc


def check_reset(spec, backend):
    """After ``reset()`` the filter behaves like a fresh one."""
    seq = _sequence(spec)
    f = _filter(spec, backend)
    for frame in seq:
        f(frame, sampler=None)
    f.reset()
    again = f(seq[0], sampler=None)
    fresh = _filter(spec, backend)(seq[0], sampler=None)
    assert np.array_equal(again, fresh), f"filter {spec.name!r}: output after reset() differs from a fresh instance"


def check_deepcopy(spec, backend):
    """A (temporal) filter can be deep-copied, and the copy continues identically (the timing protocol needs it)."""
    seq = _sequence(spec)
    f = _filter(spec, backend)
    f(seq[0], sampler=None)
    g = copy.deepcopy(f)
    for frame in seq[1:] or seq:
        a = f(frame, sampler=None)
        b = g(frame, sampler=None)
        assert np.array_equal(a, b), f"filter {spec.name!r}: a deep copy diverged from the original"


FILTER_CHECKS = [
    check_output_shape_dtype,
    check_input_not_modified,
    check_deterministic,
    check_constant_image,
    check_zero_image,
    check_fireflies,
    check_huge_values,
    check_tiny_values,
    check_float16_range,
    check_sizes,
    check_reset,
    check_deepcopy,
]


# ---------------------------------------------------------------- metrics
def check_metric_identical_best(spec, backend=None):
    """Identical images score at least as well as a perturbed pair, and finite."""
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.0, 1.0, (16, 16, 3)).astype(np.float32)
    noisy = np.clip(ref + rng.normal(0, 0.2, ref.shape), 0, None).astype(np.float32)
    metric = spec.factory()
    if spec.kind == "sequence":
        same = metric([ref, ref * 0.9, ref], [ref, ref * 0.9, ref])
        diff = metric([ref, noisy, ref], [ref, ref * 0.9, ref])
    else:
        same, diff = metric(ref, ref), metric(noisy, ref)
    assert np.isfinite(diff), f"metric {spec.name!r} gave {diff} on finite images"
    better = same >= diff if spec.higher_is_better else same <= diff
    assert better and same != diff, f"metric {spec.name!r}: identical images scored {same}, perturbed {diff}"


def check_metric_symmetric_inputs_untouched(spec, backend=None):
    """The metric does not modify its inputs."""
    rng = np.random.default_rng(2)
    a = rng.uniform(0, 1, (8, 8, 3)).astype(np.float32)
    b = rng.uniform(0, 1, (8, 8, 3)).astype(np.float32)
    a0, b0 = a.copy(), b.copy()
    metric = spec.factory()
    metric([a, b], [b, a]) if spec.kind == "sequence" else metric(a, b)
    assert np.array_equal(a, a0) and np.array_equal(b, b0), f"metric {spec.name!r} modified its inputs"


METRIC_CHECKS = [check_metric_identical_best, check_metric_symmetric_inputs_untouched]


# ---------------------------------------------------------------- renderers
def _scene_for(registry, spec):
    candidates = [s for _, s in sorted(registry.scenes.items())
                  if s.kind in spec.scene_kinds and s.tier in spec.scene_tiers]
    if not candidates:
        return None
    return min(candidates, key=lambda s: s.resolution[0] * s.resolution[1] * s.frames).factory()


def check_renderer_provides(spec, backend=None, registry=None):
    """A render with every declared channel returns exactly those channels, valid; none asked gives colour only."""
    scene = _scene_for(registry, spec)
    if scene is None:
        return
    renderer = spec.factory()
    frame = renderer.render(scene, 0, spp=1, seed=3, channels=spec.provides, resolution=(12, 8))
    assert frame.channels == spec.provides | {"color"}, (
        f"renderer {spec.name!r} declared {sorted(spec.provides)}, produced {sorted(frame.channels)}"
    )
    assert frame.shape == (8, 12), f"renderer {spec.name!r} ignored the resolution: {frame.shape}"
    bare = renderer.render(scene, 0, spp=1, seed=3, channels=frozenset(), resolution=(12, 8))
    assert bare.channels == {"color"}, (
        f"renderer {spec.name!r} made unrequested channels {sorted(bare.channels - {'color'})}"
    )


def check_renderer_deterministic(spec, backend=None, registry=None):
    """The same seed gives bit-identical frames (and references)."""
    scene = _scene_for(registry, spec)
    if scene is None:
        return
    r = spec.factory()
    a = r.render(scene, 0, spp=2, seed=5, channels=spec.provides, resolution=(12, 8))
    b = spec.factory().render(scene, 0, spp=2, seed=5, channels=spec.provides, resolution=(12, 8))
    for name in a.channels:
        assert np.array_equal(a[name], b[name], equal_nan=True), (
            f"renderer {spec.name!r}: channel {name!r} differs between runs"
        )
    if spec.references:
        ra = r.reference(scene, 0, spp=4, seed=1, resolution=(12, 8))
        rb = r.reference(scene, 0, spp=4, seed=1, resolution=(12, 8))
        assert ra.shape == (8, 12, 3) and ra.dtype == np.float32, (
            f"renderer {spec.name!r}: reference {ra.shape} {ra.dtype}"
        )
        assert np.array_equal(ra, rb), f"renderer {spec.name!r}: references differ between runs"


RENDERER_CHECKS = [check_renderer_provides, check_renderer_deterministic]


# ---------------------------------------------------------------- scenes
def check_scene_builds(spec, backend=None):
    """The factory builds the declared scene, and its content hash is stable."""
    a, b = spec.factory(), spec.factory()
    assert a.name == spec.name, f"scene {spec.name!r}: factory built {a.name!r}"
    assert a.kind == spec.kind, f"scene {spec.name!r}: declared kind {spec.kind!r}, built {a.kind!r}"
    assert a.frame_count == spec.frames, f"scene {spec.name!r}: declared {spec.frames} frames, built {a.frame_count}"
    assert a.content_hash() == b.content_hash(), f"scene {spec.name!r}: content hash differs between builds"


SCENE_CHECKS = [check_scene_builds]

__all__ = ["FILTER_CHECKS", "METRIC_CHECKS", "RENDERER_CHECKS", "SCENE_CHECKS"]
