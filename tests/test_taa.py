"""The ``taa`` filter: convergence, the jitter convention, clipping against ghosts, disocclusion,
camera cuts, and agreement of the CPU and CUDA-simulated backends."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from harness import CameraPath, Frame, FrameMeta, load_plugins

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def _taa(registry, **params):
    f = registry.get("filter", "taa").factory(backend="cpu", **params)
    f.reset()
    return f


def _frame(color, depth=None, object_id=None, motion=None, index=1, jitter=(0.0, 0.0), cut=False):
    h, w = color.shape[:2]
    channels = {
        "color": np.asarray(color, np.float32),
        "depth": np.full((h, w), 2.0, np.float32) if depth is None else np.asarray(depth, np.float32),
        "object_id": np.zeros((h, w), np.int32) if object_id is None else np.asarray(object_id, np.int32),
        "motion": np.zeros((h, w, 2), np.float32) if motion is None else np.asarray(motion, np.float32),
    }
    return Frame(channels, FrameMeta(index=index, jitter=tuple(jitter), camera_cut=cut or index == 0))


def _static(scene):
    """The scene with its first camera position and every object frozen."""
    cam = scene.camera
    scene.camera = CameraPath(positions=cam.positions[:1], targets=cam.targets[:1], fov=cam.fov, near=cam.near,
                              far=cam.far)
    for obj in scene.objects:
        obj.transforms = None if obj.transforms is None else obj.transform(0)
    scene._hash = None
    return scene


def _rmse(a, b):
    return float(np.sqrt(np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)))


@pytest.fixture(scope="module")
def static_sequence(registry):
    scene = _static(registry.get("scene", "aa-fence").factory())
    raster = registry.get("renderer", "raster").factory(jitter=True)
    size = (96, 54)
    frames = [raster.render(scene, t, channels={"depth", "object_id", "motion"}, resolution=size) for t in range(17)]
    return frames, raster.reference(scene, 0, resolution=size)


@pytest.mark.parametrize("params", [{}, {"clipping": "none"}])
def test_static_jittered_sequence_converges_toward_ssaa(registry, static_sequence, params):
    frames, ref = static_sequence
    f = _taa(registry, **params)
    errors = [_rmse(f(frame), ref) for frame in frames]
    assert errors[16] < 0.75 * errors[0], errors
    assert errors[16] < 0.6 * _rmse(frames[16]["color"], ref), "better than any single aliased frame"


def test_surface_motion_includes_the_jitter_and_taa_removes_it(registry, static_sequence):
    # a static scene: surface motion equals the jitter, so the history is fetched exactly at the
    # pixel and the plain TAA output is the exponential moving average of the frames
    frames, _ = static_sequence
    surface = np.isfinite(frames[5]["depth"])
    np.testing.assert_allclose(frames[5]["motion"][surface], np.broadcast_to(frames[5].meta.jitter, (surface.sum(), 2)),
                               atol=1e-4)
    f = _taa(registry, clipping="none", reconstruct=False, luminance_weighting=False, history_filter="catmull_rom")
    expected = frames[0]["color"].astype(np.float64)
    for t, frame in enumerate(frames[:8]):
        out = f(frame)
        if t:
            expected = 0.1 * frame["color"] + 0.9 * expected
        np.testing.assert_allclose(out, expected, atol=2e-4 * max(1.0, float(expected.max())))


def _moving_spot(t, h=24, w=48, speed=2.0):
    """A bright disc moving right over a dark flat plane: a shading change the G-buffer does not see."""
    yy, xx = np.mgrid[0:h, 0:w]
    inside = (xx - (6.0 + speed * t)) ** 2 + (yy - h / 2) ** 2 < 16.0
    color = np.full((h, w, 3), 0.1, np.float32)
    color[inside] = (0.9, 0.8, 0.2)
    return color, inside


def test_variance_clipping_removes_the_ghost_that_plain_blending_leaves(registry):
    ghosts = {}
    for clipping in ("none", "variance", "minmax"):
        f = _taa(registry, clipping=clipping)
        for t in range(12):
            color, inside = _moving_spot(t)
            out = f(_frame(color, index=t))
        # the region the spot left during the last 4 frames
        left = np.zeros_like(inside)
        for k in range(1, 5):
            left |= _moving_spot(11 - k)[1]
        near = np.zeros_like(inside)  # within 2 px of the spot: its neighbourhood holds the spot
        for dy in range(-2, 3):
            for dx in range(-2, 3):
                near |= np.roll(np.roll(inside, dy, 0), dx, 1)
        trail = left & ~near
        ghosts[clipping] = float(np.abs(out[trail] - 0.1).max())
    assert ghosts["none"] > 0.1, ghosts
    assert ghosts["variance"] < 0.01 and ghosts["minmax"] < 0.01, ghosts


def test_disoccluded_history_is_rejected_by_depth_and_object_id(registry):
    h, w = 20, 40
    rng = np.random.default_rng(3)
    background = rng.uniform(0.2, 0.8, (h, w, 3)).astype(np.float32)
    f = _taa(registry, clipping="none", reconstruct=False)

    def occluded(x0):
        color = background.copy()
        depth = np.full((h, w), 5.0, np.float32)
        ids = np.zeros((h, w), np.int32)
        color[5:15, x0:x0 + 8] = (1.0, 0.0, 0.0)
        depth[5:15, x0:x0 + 8] = 1.0
        ids[5:15, x0:x0 + 8] = 1
        return color, depth, ids

    for t, x0 in enumerate((4, 4, 4, 10)):
        color, depth, ids = occluded(x0)
        motion = np.zeros((h, w, 2), np.float32)
        if t == 3:  # the occluder moved 6 px right: its pixels come from 6 px to the left
            motion[5:15, 10:18, 0] = -6.0
        out = f(_frame(color, depth, ids, motion, index=t))
    uncovered = np.zeros((h, w), bool)
    # (the rim next to pixels that showed the background, and the column next to the occluder,
    # which takes the occluder's motion by dilation, are left to clipping)
    uncovered[6:14, 5:9] = True
    # the background behind the old position was hidden: its history is rejected
    np.testing.assert_allclose(out[uncovered], color[uncovered], atol=1e-5)
    # and the moved occluder keeps its own history (reprojected by its motion): still red
    np.testing.assert_allclose(out[6:14, 11:17], np.broadcast_to([1.0, 0.0, 0.0], (8, 6, 3)), atol=1e-5)
    # without the test (an infinite tolerance and one object id) the red history would stay
    f = _taa(registry, clipping="none", reconstruct=False, depth_tolerance=1e30)
    for t, x0 in enumerate((4, 4, 4, 10)):
        color, depth, _ = occluded(x0)
        motion = np.zeros((h, w, 2), np.float32)
        out = f(_frame(color, depth, np.zeros((h, w), np.int32), motion, index=t))
    assert out[uncovered][:, 0].mean() > color[uncovered][:, 0].mean() + 0.2


def test_camera_cut_and_reset_drop_the_history(registry):
    rng = np.random.default_rng(0)
    frames = [_frame(rng.uniform(0, 1, (10, 12, 3)), index=t) for t in range(4)]
    cut = _frame(rng.uniform(0, 1, (10, 12, 3)), index=4, cut=True)
    f = _taa(registry)
    for frame in frames:
        f(frame)
    np.testing.assert_array_equal(f(cut), _taa(registry)(cut))
    # reconstruction alone on a cut frame: the Blackman-Harris mean of the 3x3 samples
    g = _taa(registry, reconstruct=False)
    np.testing.assert_allclose(g(cut), cut["color"], rtol=1e-6)


def test_integer_camera_pan_is_followed_exactly(registry):
    rng = np.random.default_rng(1)
    world = rng.uniform(0.0, 1.0, (16, 60, 3)).astype(np.float32)
    f = _taa(registry, clipping="none", reconstruct=False, luminance_weighting=False)
    motion = np.zeros((16, 40, 2), np.float32)
    motion[..., 0] = 3.0  # the view pans right: what is at x now was at x + 3 in the previous image
    for t in range(5):
        color = world[:, 3 * t:3 * t + 40]
        out = f(_frame(color, motion=motion, index=t))
        # the history holds the same world texels (fetched at integer offsets, so exactly):
        # the blend of equal values is the input, and the columns entering the view have none
        np.testing.assert_allclose(out, color, atol=1e-6)


def test_luminance_weighting_keeps_single_colours_exact_and_bounds_the_output(registry):
    rng = np.random.default_rng(2)
    f = _taa(registry)
    outs = []
    frames = []
    for t in range(6):
        color = rng.exponential(1.0, (12, 14, 3)).astype(np.float32)
        color[3, 4] = 5e4  # a sparkle
        frames.append(_frame(color, index=t))
        outs.append(f(frames[-1]))
    top = max(float((0.25 * fr["color"][..., 0] + 0.5 * fr["color"][..., 1] + 0.25 * fr["color"][..., 2]).max())
              for fr in frames)
    for out in outs:
        assert np.isfinite(out).all() and (out >= 0).all()
        luma = 0.25 * out[..., 0] + 0.5 * out[..., 1] + 0.25 * out[..., 2]
        assert luma.max() <= top * (1 + 1e-5)


def test_parameters_are_validated(registry):
    with pytest.raises(ValueError, match="alpha"):
        _taa(registry, alpha=0.0)
    with pytest.raises(ValueError, match="clipping"):
        _taa(registry, clipping="box")
    with pytest.raises(TypeError, match="unknown"):
        _taa(registry, sharpen=1.0)
    spec = registry.get("filter", "taa")
    assert spec.tasks == {"antialias"} and spec.temporal and spec.backends == ("cpu", "cuda")


@pytest.mark.slow
def test_cuda_simulator_agrees_with_cpu():
    script = textwrap.dedent(
        """
        import numpy as np
        from harness import Frame, FrameMeta, load_plugins
        spec = load_plugins().get("filter", "taa")
        rng = np.random.default_rng(5)
        h, w = 9, 13
        frames = []
        for t in range(3):
            depth = rng.uniform(1.0, 3.0, (h, w)).astype(np.float32)
            depth[0, :4] = np.inf
            ids = (depth > 2.0).astype(np.int32)
            ids[0, :4] = -1
            motion = rng.normal(0.0, 1.2, (h, w, 2)).astype(np.float32)
            color = rng.exponential(0.5, (h, w, 3)).astype(np.float32)
            jitter = (float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5)))
            frames.append(Frame({"color": color, "depth": depth, "object_id": ids, "motion": motion},
                                FrameMeta(index=t, jitter=jitter, camera_cut=t == 0)))
        for params in ({}, {"clipping": "minmax", "history_filter": "bilinear", "luminance_weighting": False},
                       {"clipping": "none", "reconstruct": False, "dilate_motion": False}):
            cpu = spec.factory(backend="cpu", **params)
            gpu = spec.factory(backend="cuda", **params)
            for frame in frames:
                a, b = cpu(frame), gpu(frame)
                assert np.allclose(a, b, rtol=1e-5, atol=1e-6), (params, frame.meta.index, np.abs(a - b).max())
        print("AGREE")
        """
    )
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    proc = subprocess.run([sys.executable, "-c", script], env=env, cwd=ROOT, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0 and "AGREE" in proc.stdout, proc.stderr[-3000:]
