"""Motion of static geometry from the camera (issue 32): :func:`harness.camera_motion` and SVGF.

A capture without ``motion`` but with its camera (``view_proj``, ``prev_view_proj``) and
``depth`` or ``position`` gets the motion vectors of its static geometry. On ``atrium`` with its
objects held still (only the camera moves) they equal the renderers' ``motion`` channel at every
pixel (from ``position`` exactly, from ``depth`` within 1e-4 px: measured 0.0 and 3.5e-6 px at
64x48, frame 4, with and without jitter); with the objects moving they equal it on the static
objects' pixels. SVGF then keeps its history, and on a sequence without ``motion`` its output
equals (within float rounding) SVGF fed the renderer's motion.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from harness import (
    CHANNELS,
    CameraPath,
    Frame,
    FrameMeta,
    camera_motion,
    camera_motion_ready,
    load_plugins,
    static_motion,
)

SIZE = (64, 48)
GBUFFER = frozenset({"depth", "position", "object_id", "motion"})
CAPTURE = frozenset({"color", "albedo", "normal"})


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def still(scene):
    """``scene`` with every object held at its first frame's place: only the camera moves."""
    objects = [dataclasses.replace(o, transforms=None if o.transforms is None else o.transforms[:1])
               for o in scene.objects]
    return dataclasses.replace(scene, objects=objects)


@pytest.fixture(scope="module")
def atrium(registry):
    return registry.scenes["atrium"].factory()


@pytest.fixture(scope="module")
def still_atrium(atrium):
    return still(atrium)


def render_at(registry, renderer, options, scene, t, channels=GBUFFER):
    """Frame ``t`` of ``scene`` and the jitter of frame ``t - 1`` (the jitter in its prev_view_proj)."""
    r = registry.renderers[renderer].factory(**options)
    before = r.render(scene, t - 1, channels={"depth"}, resolution=SIZE)
    return r.render(scene, t, channels=channels, resolution=SIZE), before.meta.jitter


RENDERERS = [("raster", {}), ("pathtracer", {}), ("pathtracer", {"jitter": True})]


@pytest.mark.parametrize("renderer, options", RENDERERS, ids=["raster", "pathtracer", "pathtracer-jitter"])
def test_equals_the_renderers_motion_where_only_the_camera_moves(registry, still_atrium, renderer, options):
    frame, prev_jitter = render_at(registry, renderer, options, still_atrium, 4)
    truth = frame["motion"]
    assert np.abs(truth).max() > 0.5  # the camera moves
    assert (frame["object_id"] < 0).any()  # sky: the direction at infinity
    from_position = camera_motion(frame, prev_jitter)
    from_depth = camera_motion(frame.subset({"depth"}), prev_jitter)
    assert np.abs(from_position - truth).max() <= 1e-5
    assert np.abs(from_depth - truth).max() <= 1e-4
    if options.get("jitter"):  # the previous frame's jitter is in prev_view_proj: it must be known
        assert np.abs(camera_motion(frame, (0.0, 0.0)) - truth).max() > 0.05


def test_equals_the_renderers_motion_on_static_pixels_where_objects_move(registry, atrium):
    frame, prev_jitter = render_at(registry, "raster", {}, atrium, 4)
    moving = [k for k, o in enumerate(atrium.objects) if o.transforms is not None]
    on_moving = np.isin(frame["object_id"], moving)
    assert on_moving.any() and not on_moving.all()
    error = np.abs(camera_motion(frame.subset({"depth"}), prev_jitter) - frame["motion"]).max(axis=-1)
    assert error[~on_moving].max() <= 1e-4
    assert error[on_moving].max() > 0.1  # the objects' own motion is not the camera's


def _camera(eyes, targets, fov=50.0):
    return CameraPath(positions=eyes, targets=targets, fov=fov, near=0.1, far=100.0)


def _matrices(camera, w, h):
    return camera.view_projection(1, w, h), camera.view_projection(0, w, h)


def test_a_sideways_step_moves_every_pixel_by_the_analytic_amount():
    w, h, z, step = 40, 30, 4.0, 0.25
    camera = _camera([(0, 0, 0), (step, 0, 0)], [(0, 0, -1), (step, 0, -1)])
    vp, prev = _matrices(camera, w, h)
    depth = np.full((h, w), z, np.float32)
    depth[:5] = np.inf  # sky: the camera does not turn, so it does not move
    motion = static_motion(vp, prev, depth=depth)
    f = 1.0 / np.tan(np.radians(50.0) / 2.0)
    want = f / (w / h) * step / z * w / 2.0  # the point was further right in the previous image
    np.testing.assert_allclose(motion[5:, :, 0], want, rtol=1e-5)
    np.testing.assert_allclose(motion[5:, :, 1], 0.0, atol=1e-5)
    np.testing.assert_allclose(motion[:5], 0.0, atol=1e-5)
    np.testing.assert_allclose(static_motion(vp, vp, depth=depth), 0.0, atol=1e-5)  # camera still


def test_points_behind_the_previous_camera_go_outside_the_previous_image():
    w, h = 24, 16
    camera = _camera([(0, 0, 0), (0, 0, 0)], [(0, 0, 1), (0, 0, -1)])  # turned round
    vp, prev = _matrices(camera, w, h)
    depth = np.full((h, w), 3.0, np.float32)
    depth[0] = np.inf
    motion = static_motion(vp, prev, depth=depth)
    ii, jj = np.mgrid[0:h, 0:w]
    np.testing.assert_array_equal(jj + motion[..., 0], -(w + h))
    np.testing.assert_array_equal(ii + motion[..., 1], -(w + h))


def test_bad_depths_positions_and_matrices_give_finite_motion_or_none():
    rng = np.random.default_rng(7)
    w, h = 13, 9
    specials = np.array([np.nan, np.inf, -np.inf, 0.0, -1.0, 1e-30, 1e30, 3.4e38, 1e-3], np.float32)
    for trial in range(200):
        if trial % 2:
            vp, prev = rng.normal(size=(4, 4)), rng.normal(size=(4, 4))
        else:
            eyes, targets = rng.normal(scale=5.0, size=(2, 3)), rng.normal(scale=5.0, size=(2, 3))
            vp, prev = _matrices(_camera(eyes, targets, fov=rng.uniform(5, 170)), w, h)
        depth = rng.exponential(5.0, size=(h, w)).astype(np.float32)
        depth.flat[rng.choice(h * w, 40, replace=False)] = rng.choice(specials, 40)
        position = rng.normal(scale=10.0 ** rng.uniform(-3, 30), size=(h, w, 3)).astype(np.float32)
        position.flat[rng.choice(h * w * 3, 20, replace=False)] = rng.choice(specials, 20)
        jitter = tuple(rng.uniform(-0.5, 0.5, 2))
        for kwargs in ({"depth": depth}, {"position": position, "background": depth == np.inf}):
            motion = static_motion(vp, prev, jitter=jitter, prev_jitter=jitter, **kwargs)
            if motion is None:
                continue
            assert motion.shape == (h, w, 2) and motion.dtype == np.float32 and np.isfinite(motion).all()
            ii, jj = np.mgrid[0:h, 0:w]
            x, y = jj + motion[..., 0], ii + motion[..., 1]
            margin = w + h
            assert x.min() >= -margin - 1e-3 and x.max() <= w - 1 + margin + 1e-3
            assert y.min() >= -margin - 1e-3 and y.max() <= h - 1 + margin + 1e-3


def test_none_without_a_perspective_camera():
    w, h = 8, 6
    vp, prev = _matrices(_camera([(0, 0, 0), (1, 0, 0)], [(0, 0, -1), (1, 0, -1)]), w, h)
    depth = np.ones((h, w), np.float32)
    ortho = np.diag([1.0, 1.0, -1.0, 1.0])
    broken = vp.copy()
    broken[0, 0] = np.nan
    assert static_motion(vp, prev, depth=depth) is not None
    for a, b in [(None, prev), (vp, None), (ortho, prev), (vp, ortho), (broken, prev), (vp, broken),
                 (np.zeros((4, 4)), prev), (vp[:3], prev)]:
        assert static_motion(a, b, depth=depth) is None
    assert static_motion(vp, prev) is None  # neither depth nor position
    colour = np.zeros((h, w, 3), np.float32)
    assert camera_motion(Frame({"color": colour, "depth": depth})) is None  # no matrices in the metadata
    meta = FrameMeta(view_proj=vp, prev_view_proj=prev)
    assert camera_motion(Frame({"color": colour}, meta)) is None  # no depth or position
    assert camera_motion(Frame({"color": colour, "depth": depth}, meta)).shape == (h, w, 2)


def test_background_with_position_alone_is_the_zero_position():
    w, h = 16, 12
    camera = _camera([(0, 0, 0), (0, 0, 0)], [(0.3, 0, -1), (0, 0, -1)])  # a turn: the sky moves
    vp, prev = _matrices(camera, w, h)
    depth = np.full((h, w), np.inf, np.float32)
    sky = static_motion(vp, prev, depth=depth)
    meta = FrameMeta(view_proj=vp, prev_view_proj=prev)
    frame = Frame({"color": np.zeros((h, w, 3), np.float32), "position": np.zeros((h, w, 3), np.float32)}, meta)
    np.testing.assert_allclose(camera_motion(frame), sky, atol=1e-4)
    assert np.abs(sky).max() > 1.0


def test_ready_needs_depth_or_position_and_both_matrices_after_each_cut():
    vp = np.eye(4)
    vp[3] = (0.0, 0.0, -1.0, 0.0)
    good = FrameMeta(view_proj=vp, prev_view_proj=vp)
    first = FrameMeta(camera_cut=True)  # a cut needs no previous camera
    assert camera_motion_ready({"depth"}, [first, good, good])
    assert camera_motion_ready({"position"}, [good])
    assert not camera_motion_ready({"normal"}, [first, good])
    assert not camera_motion_ready({"depth"}, [first])  # no frame that could use history
    assert not camera_motion_ready({"depth"}, [first, good, FrameMeta(view_proj=vp)])
    assert not camera_motion_ready({"depth"}, [good, FrameMeta(view_proj=vp, prev_view_proj=np.zeros((4, 4)))])


def test_the_guides_column_names_camera_motion(registry):
    svgf = registry.filters["svgf"]
    vp = np.eye(4)
    vp[3] = (0.0, 0.0, -1.0, 0.0)
    metas = [FrameMeta(camera_cut=True, view_proj=vp), FrameMeta(view_proj=vp, prev_view_proj=vp)]
    assert svgf.motion_from_camera
    derived = "albedo,depth,motion(camera),normal; without motion,object_id"
    assert svgf.guides_used(CAPTURE | {"depth"}, metas) == derived
    assert svgf.guides_used(CAPTURE | {"depth"}, [FrameMeta()] * 2) == "albedo,depth,normal; without motion,object_id"
    assert svgf.guides_used(CAPTURE | {"depth"}) == "albedo,depth,normal; without motion,object_id"
    # svgf does not read position, so position alone gives it nothing to unproject
    assert svgf.guides_used(CAPTURE | {"position"}, metas) == "albedo,normal; without depth,motion,object_id"
    assert svgf.guides_used(CHANNELS, metas) == "albedo,depth,emission,indirect,motion,normal,object_id"
    assert registry.filters["eaw"].guides_used(CAPTURE | {"depth"}, metas) == "albedo,depth,normal; without position"


def test_a_run_on_a_capture_without_motion_names_camera_motion(registry, still_atrium, tmp_path):
    """A capture with depth and its camera matrices, and one without the matrices, through
    ``run_benchmark``: the rows say which mode SVGF ran."""
    from harness import write_capture
    from harness.benchmark import run_benchmark

    tracer = registry.renderers["pathtracer"].factory()
    frames = [tracer.render(still_atrium, t, channels={"albedo", "normal", "depth"}, resolution=(32, 24))
              for t in range(3)]
    refs = [f["color"] for f in frames]
    write_capture(tmp_path / "camera", frames, refs, name="camera", spp=1)
    write_capture(tmp_path / "blind", [f.with_meta(view_proj=None, prev_view_proj=None) for f in frames], refs,
                  name="blind", spp=1)
    table = run_benchmark(out=tmp_path / "o", registry=registry, scenes=[], scene_dirs=[tmp_path / "camera",
                          tmp_path / "blind"], filters=["svgf"], metrics=["rmse"], executor="inline",
                          cache_dir=tmp_path / "c", seeds=[0], timing_at=()).table
    assert set(table.status) == {"ok"}
    guides = table.groupby("scene").guides.agg(set).to_dict()
    assert guides == {"camera": {"albedo,depth,motion(camera),normal; without motion,object_id"},
                      "blind": {"albedo,depth,normal; without motion,object_id"}}


def test_the_leaderboard_keeps_camera_motion_apart_from_spatial_only():
    import pandas as pd

    from harness.results import entry_labels

    guides = ["albedo,depth,motion,normal,object_id", "albedo,depth,motion(camera),normal; without motion,object_id",
              "albedo,depth,normal; without motion,object_id"]
    df = pd.DataFrame({"filter": "svgf", "preset": "", "backend": "cpu", "params": "{}", "spp": 1, "guides": guides})
    assert list(entry_labels(df)) == ["svgf/cpu", "svgf/cpu [without motion,object_id; motion(camera)]",
                                      "svgf/cpu [without motion,object_id]"]


def _svgf_run(registry, frames):
    filt = registry.filters["svgf"].factory(backend="cpu")
    filt.reset()
    outs = [filt(f) for f in frames]
    return outs, filt


@pytest.fixture(scope="module")
def camera_only_sequence(registry, still_atrium):
    tracer = registry.renderers["pathtracer"].factory(jitter=True)
    channels = {"albedo", "normal", "depth", "position", "motion"}
    return [tracer.render(still_atrium, t, seed=5, channels=channels, resolution=SIZE) for t in range(4)]


def test_svgf_without_motion_follows_the_camera_as_with_the_renderers_motion(registry, camera_only_sequence):
    frames = camera_only_sequence
    full, _ = _svgf_run(registry, [f.subset(f.channels - {"position"}) for f in frames])
    for drop in ({"motion", "position"}, {"motion"}):  # depth alone; position (and depth)
        derived, filt = _svgf_run(registry, [f.subset(f.channels - drop) for f in frames])
        assert filt.history_length().max() == 4.0 and "camera_motion" in filt.stage_ms
        for a, b in zip(full, derived):
            np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)
    blind = [f.subset(f.channels - {"motion"}).with_meta(view_proj=None, prev_view_proj=None) for f in frames]
    spatial, filt = _svgf_run(registry, blind)
    assert filt.history_length().max() <= 1.0 and "camera_motion" not in filt.stage_ms
    assert np.abs(spatial[-1] - full[-1]).max() > 1e-2


@pytest.mark.slow
def test_svgf_with_camera_motion_beats_spatial_only_on_a_moving_camera(registry, still_atrium):
    """8 frames at 64x64 (1 spp, seed 0; references 32 spp, seed 1) of atrium held still: measured
    temporal_error 0.1216 with camera motion and 0.1892 spatial only, display_rmse (mean of the
    frames) 0.1119 and 0.1490 (with the renderer's motion: the same as camera motion to 4 digits)."""
    from plugins.metrics.errors import display_rmse
    from plugins.metrics.temporal import temporal_error

    scene, size = still_atrium, (64, 64)
    tracer = registry.renderers["pathtracer"].factory()
    frames = [tracer.render(scene, t, seed=0, channels={"albedo", "normal", "depth", "indirect", "emission"},
                            resolution=size) for t in range(8)]
    refs = [tracer.reference(scene, t, spp=32, seed=1, resolution=size) for t in range(8)]
    camera, _ = _svgf_run(registry, frames)
    spatial, _ = _svgf_run(registry, [f.with_meta(view_proj=None, prev_view_proj=None) for f in frames])

    def rmse(outs):
        return float(np.mean([display_rmse(o, r) for o, r in zip(outs, refs)]))

    assert temporal_error(camera, refs) < 0.8 * temporal_error(spatial, refs)
    assert rmse(camera) <= rmse(spatial)
