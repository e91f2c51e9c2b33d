"""The synthetic renderer: exact references, exact noise variance, exact motion, sample streams."""

import numpy as np
import pytest

from harness import CHANNELS
from harness.testing import registry

RES = (40, 30)


@pytest.fixture(scope="module")
def synth():
    reg = registry()
    return reg.renderers["synthetic"].factory(), {
        n: reg.scenes[n].factory() for n in ("synthetic-edges", "synthetic-moving")
    }


def test_noise_is_unbiased_with_the_declared_variance(synth):
    renderer, scenes = synth
    scene = scenes["synthetic-edges"]
    ref = renderer.reference(scene, 0, resolution=RES)
    samples = np.stack(
        [renderer.render(scene, 0, spp=2, seed=s, channels={"variance"}, resolution=RES)["color"] for s in range(400)]
    )
    var = renderer.render(scene, 0, spp=2, seed=0, channels={"variance"}, resolution=RES)["variance"]
    noisy = var > 0
    # mean: within 5 standard errors everywhere
    z = np.abs(samples.mean(0) - ref)[noisy] / np.sqrt(var[noisy] / 400)
    assert z.max() < 5.5
    # variance: the sample variance over 400 seeds matches the declared one to ~15% on average
    ratio = samples.var(0, ddof=1)[noisy] / var[noisy]
    assert abs(np.mean(ratio) - 1.0) < 0.05
    # noise-free pixels (sky) are exact
    assert np.array_equal(samples[0][~noisy], ref[~noisy])


def test_more_samples_continue_the_same_streams(synth):
    renderer, scenes = synth
    scene = scenes["synthetic-moving"]
    full = renderer.render(scene, 3, spp=16, seed=7, channels={"variance", "spp"}, resolution=RES)
    sampler = renderer.sampler(scene, 3, spp=8, seed=7, channels={"variance"}, resolution=RES)
    more = sampler.add_samples(np.full(RES[::-1], 8, np.int32))
    assert np.array_equal(more["color"], full["color"]) and np.array_equal(more["spp"], full["spp"])
    assert sampler.samples_used == 16 * RES[0] * RES[1]
    acc = renderer.accumulate(scene, 3, first_sample=0, count=16, seed=7, resolution=RES)
    np.testing.assert_allclose(acc / 16, full["color"], rtol=2e-6, atol=1e-6)


def test_uneven_extra_samples_are_counted(synth):
    renderer, scenes = synth
    sampler = renderer.sampler(scenes["synthetic-edges"], 0, spp=1, seed=0, channels=set(), resolution=RES)
    extra = np.zeros(RES[::-1], np.int32)
    extra[:5, :7] = 3
    frame = sampler.add_samples(extra)
    assert sampler.samples_used == RES[0] * RES[1] + 3 * 35
    assert frame["spp"][0, 0] == 4 and frame["spp"][-1, -1] == 1
    with pytest.raises(ValueError, match=">= 0"):
        sampler.add_samples(-extra)


def test_motion_vectors_warp_the_previous_frame_onto_the_current(synth):
    renderer, scenes = synth
    scene = scenes["synthetic-moving"]
    w, h = 160, 120
    cur = renderer.render(scene, 5, spp=1, seed=0, channels={"motion", "object_id", "albedo"}, resolution=(w, h))
    prev = renderer.render(scene, 4, spp=1, seed=0, channels={"object_id", "albedo"}, resolution=(w, h))
    mv = cur["motion"]
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    px = np.rint(jj + mv[..., 0]).astype(int)
    py = np.rint(ii + mv[..., 1]).astype(int)
    inside = (px >= 0) & (px < w) & (py >= 0) & (py < h)
    same = np.zeros_like(inside)
    same[inside] = prev["object_id"][py[inside], px[inside]] == cur["object_id"][inside]
    # everything that stays in view lands on the same object, except a thin band of disocclusion
    assert same[inside].mean() > 0.97
    assert np.abs(mv[cur["object_id"] == 0][:, 0] - 0.01 * w).max() < 1e-3  # the pan, exactly


def test_renders_only_what_was_asked_and_is_deterministic(synth):
    renderer, scenes = synth
    scene = scenes["synthetic-edges"]
    a = renderer.render(scene, 0, spp=1, seed=3, channels={"normal"}, resolution=RES)
    assert a.channels == {"color", "normal"}
    b = renderer.render(scene, 0, spp=1, seed=3, channels=set(CHANNELS), resolution=RES)
    assert np.array_equal(a["color"], b["color"])
    c = renderer.render(scene, 0, spp=1, seed=4, channels=set(), resolution=RES)
    assert not np.array_equal(a["color"], c["color"])
    np.testing.assert_allclose(b["direct"] + b["indirect"], b["color"], rtol=1e-5, atol=1e-6)
    bg = b["object_id"] == -1
    assert bg.any() and np.isposinf(b["depth"][bg]).all() and (b["normal"][bg] == 0).all()
    n = np.linalg.norm(b["normal"][~bg], axis=-1)
    np.testing.assert_allclose(n, 1.0, rtol=1e-6)


def test_rejects_mesh_scenes_and_bad_spp(synth):
    from harness import Scene

    renderer, scenes = synth
    with pytest.raises(ValueError, match="procedural scenes only"):
        renderer.render(Scene(name="m", kind="mesh"), 0, spp=1, seed=0, channels=set(), resolution=RES)
    with pytest.raises(ValueError, match="spp must be >= 1"):
        renderer.render(scenes["synthetic-edges"], 0, spp=0, seed=0, channels=set(), resolution=RES)
