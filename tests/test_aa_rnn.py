"""The ``aa_rnn`` filter: inference equals the training graph, reproducible training, training data
kept apart from the benchmark scenes, architecture guarantees, weights validation."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest
import torch

from harness import Frame, FrameMeta, load_plugins
from plugins.filters.aa_rnn import data as D
from plugins.filters.aa_rnn import dataset as DS
from plugins.filters.aa_rnn.dataset_training import EpochConfig
from plugins.filters.aa_rnn.network import AARNN, inverse_tonemap, prepare, unroll, warp
from plugins.filters.aa_rnn.train import QUICK, train
from plugins.filters.aa_rnn.weights import (
    DEFAULT_LAYERS,
    SHIPPED,
    WeightsError,
    arrays_digest,
    load_weights,
    model_arrays,
    save_weights,
    shipped_weights,
)


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def _random_model(layers: int, seed: int) -> AARNN:
    torch.manual_seed(seed)
    model = AARNN(layers)
    with torch.no_grad():
        for conv in list(model.body) + [model.head]:
            conv.weight.normal_(0.0, 0.08)
    return model


def _frames(count=4, h=14, w=18, seed=0, color=None, flat=False):
    rng = np.random.default_rng(seed)
    frames = []
    for t in range(count):
        depth = rng.uniform(1.0, 4.0, (h, w)).astype(np.float32)
        depth[:3, :5] = np.inf
        normal = rng.normal(0.0, 1.0, (h, w, 3)).astype(np.float32)
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        normal[:3, :5] = 0.0
        c = rng.exponential(0.6, (h, w, 3)).astype(np.float32) if color is None else np.broadcast_to(
            np.float32(color), (h, w, 3)).copy()
        if flat:
            depth[...] = 2.0
            normal[...] = (0.0, 0.0, 1.0)
        motion = rng.normal(0.0, 1.5, (h, w, 2)).astype(np.float32)
        jitter = (float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5)))
        frames.append(Frame({"color": c, "normal": normal, "depth": depth, "motion": motion},
                            FrameMeta(index=t, jitter=jitter, camera_cut=t == 0)))
    return frames


def _tensor(a):
    a = np.asarray(a, np.float32)
    return torch.from_numpy(np.array(a.reshape(a.shape[0], a.shape[1], -1).transpose(2, 0, 1)))[None]


def _prepared(frames):
    return [prepare(_tensor(f["color"]), _tensor(f["normal"]), _tensor(f["depth"]), _tensor(f["motion"]),
                    torch.tensor([f.meta.jitter], dtype=torch.float32)) for f in frames]


def _weights_file(tmp_path, model, name="w.npz"):
    return save_weights(model_arrays(model), {"seed": -1}, tmp_path / name)


@pytest.mark.slow
def test_inference_equals_the_training_graph(registry, tmp_path):
    model = _random_model(3, seed=1)
    path = _weights_file(tmp_path, model)
    filt = registry.get("filter", "aa_rnn").factory(backend="cpu", layers=3, weights=str(path))
    frames = _frames(5)
    outs = [filt(f) for f in frames]
    model.train()
    graph = unroll(model, _prepared(frames))  # gradients on: the graph back-propagation runs through
    assert graph[-1].requires_grad
    for out, u in zip(outs, graph):
        # compared in the network's tone-mapped domain (x / (1 + x)), where float32 rounding is uniform
        np.testing.assert_allclose(out / (1.0 + out), u[0].permute(1, 2, 0).detach().numpy(), atol=2e-6)
        expected = inverse_tonemap(u)[0].permute(1, 2, 0).detach().numpy()
        np.testing.assert_allclose(out, expected, rtol=1e-3)
    assert not np.allclose(outs[-1], frames[-1]["color"], atol=1e-3), "the network changes the image"


@pytest.mark.slow
def test_same_seed_gives_the_same_weights_and_another_seed_others(tmp_path):
    a = train(seed=3, output=tmp_path / "a.npz", quick=True)
    b = train(seed=3, output=tmp_path / "b.npz", quick=True)
    c = train(seed=4, output=tmp_path / "c.npz", quick=True)
    (wa, ma), (wb, mb), mc = load_weights(a), load_weights(b), load_weights(c)[1]
    assert ma["training_data_sha256"] == mb["training_data_sha256"] != mc["training_data_sha256"]
    for name in wa:
        np.testing.assert_array_equal(wa[name], wb[name])
    assert ma["arrays_sha256"] == mb["arrays_sha256"] != mc["arrays_sha256"]
    assert ma["config"]["steps"] == QUICK.steps and ma["threads"] == 1


def _shipped_dataset() -> DS.DatasetConfig:
    d = SHIPPED[DEFAULT_LAYERS]["dataset"]
    return DS.DatasetConfig(**dict(d, mitsuba=tuple(d["mitsuba"])))


def _shipped_entries(split: str, count: int) -> list[dict]:
    return [e for e in DS.plan(_shipped_dataset()) if e["split"] == split][:count]


@pytest.mark.slow
def test_shipped_training_data_holds_the_benchmark_scenes_out(registry):
    recipe = SHIPPED[DEFAULT_LAYERS]["recipe"]
    config = _shipped_dataset()
    used = _shipped_entries("train", recipe["train_sequences"]) + _shipped_entries("validation",
                                                                                   recipe["val_sequences"])
    assert len(used) == recipe["train_sequences"] + recipe["val_sequences"]
    benchmark = {name for name, spec in registry.scenes.items() if "antialias" in spec.tasks}
    assert benchmark == {"aa-railing", "aa-fence", "aa-garden"}
    sources = {e["source"] for e in used}
    assert sources == {"procedural", *config.mitsuba} and not sources & benchmark
    for name in config.mitsuba:  # crops of registered Mitsuba scenes that serve no AA benchmark
        assert "mitsuba" in registry.scenes[name].tags and "antialias" not in registry.scenes[name].tasks
    # the procedural scenes, built as the dataset builds them, are none of the benchmark scenes
    hashes = {registry.scenes[name].factory().content_hash() for name in benchmark}
    renderer = registry.get("renderer", "raster").factory(jitter=True)
    for e in [e for e in used if e["source"] == "procedural"][:6]:
        scene, _, _ = DS.build_scene(config, e, renderer)
        assert scene.name not in registry.scenes and scene.content_hash() not in hashes


def test_shipped_weights_match_their_recorded_hashes_and_recipe(registry):
    assert DEFAULT_LAYERS in SHIPPED
    for layers, recorded in SHIPPED.items():
        path = shipped_weights(layers)
        assert hashlib.sha256(path.read_bytes()).hexdigest() == recorded["file"], path.name
        arrays, meta = load_weights(path)  # checks the arrays against the digest stored in the file
        assert arrays_digest(arrays) == meta["arrays_sha256"] == recorded["arrays"]
        assert meta["training_data_sha256"] == recorded["training_data"] and meta["seed"] == recorded["seed"]
        # the recipe recorded beside the file (what `denoise-bench train aa_rnn` runs) is the file's own;
        # snapshots only write extra files
        assert meta["recipe"] == "dataset" and meta["layers"] == layers
        training = {k: v for k, v in recorded["recipe"].items() if k != "data"}
        expected = dataclasses.asdict(EpochConfig(layers=layers, **training))
        assert {k: v for k, v in meta["config"].items() if k != "snapshots"} == {
            k: v for k, v in expected.items() if k != "snapshots"}
        assert meta["epochs_run"] == training["epochs"] and meta["best_epoch"] <= training["epochs"]
    filt = registry.get("filter", "aa_rnn").factory()  # the default loads the shipped weights
    assert filt.meta["arrays_sha256"] == SHIPPED[DEFAULT_LAYERS]["arrays"]


@pytest.mark.slow
def test_shipped_weights_beat_the_aliased_input_on_held_out_dataset_sequences(registry):
    """Sequences of the shipped dataset's test split (never trained or validated on), rendered
    here: the network's SSIM against their 8x8 SSAA is well above the aliased input's."""
    config = _shipped_dataset()
    ssim = registry.get("metric", "ssim").factory()
    renderer = registry.get("renderer", "raster").factory(jitter=True)
    filt = registry.get("filter", "aa_rnn").factory()
    aliased, network = [], []
    for e in [e for e in _shipped_entries("test", 40) if e["source"] == "procedural"][:4]:
        a = DS.render_sequence(config, e, renderer)
        filt.reset()
        for t in range(config.frames):
            frame = Frame({c: a[c][t] for c in ("color", "normal", "depth", "motion")},
                          FrameMeta(index=t, jitter=tuple(float(v) for v in a["jitter"][t]), camera_cut=t == 0))
            network.append(ssim(filt(frame), a["reference"][t]))
            aliased.append(ssim(a["color"][t], a["reference"][t]))
    assert np.mean(network) > np.mean(aliased) + 0.02, (np.mean(network), np.mean(aliased))


def test_augmentation_turns_the_flow_with_the_image():
    rng = np.random.default_rng(2)
    s = 12
    window = rng.uniform(0.0, 1.0, (2, 12, s, s)).astype(np.float32)
    window[1, 7] = rng.integers(-3, 4, (s, s))  # integer flows: bilinear warps are exact lookups
    window[1, 8] = rng.integers(-3, 4, (s, s))

    def image_only(image, rotations, flip):
        padded = np.zeros((1, 12, s, s), np.float32)
        padded[0, 0:3] = image
        return D.augment(padded, rotations, flip)[0, 0:3]

    warped = warp(torch.from_numpy(window[0:1, 0:3]), torch.from_numpy(window[1:2, 7:9]),
                  torch.from_numpy(window[1:2, 0:3])).numpy()[0]
    for rotations in range(4):
        for flip in (False, True):
            aug = D.augment(window, rotations, flip)
            warped_aug = warp(torch.from_numpy(aug[0:1, 0:3]), torch.from_numpy(aug[1:2, 7:9]),
                              torch.from_numpy(aug[1:2, 0:3])).numpy()[0]
            np.testing.assert_allclose(warped_aug, image_only(warped, rotations, flip), atol=1e-6)


@pytest.mark.parametrize("layers", [1, 3])
def test_any_weights_keep_constant_images_constant_and_black_black(tmp_path, registry, layers):
    path = _weights_file(tmp_path, _random_model(layers, seed=layers))
    for color in (0.0, 0.7, 3.0):
        filt = registry.get("filter", "aa_rnn").factory(layers=layers, weights=str(path))
        for f in _frames(4, color=color, flat=True):  # constant normals and depth as well
            out = filt(f)
            assert np.abs(out - np.float32(color)).max() <= 1e-5 * max(1.0, color)
            if color == 0.0:
                assert (out == 0.0).all()


def test_black_stays_black_over_any_geometry(registry, tmp_path):
    path = _weights_file(tmp_path, _random_model(2, seed=9))
    filt = registry.get("filter", "aa_rnn").factory(layers=2, weights=str(path))
    for f in _frames(3, color=0.0):
        assert (filt(f) == 0.0).all()


def test_weights_files_are_validated(tmp_path, registry):
    path = _weights_file(tmp_path, _random_model(2, seed=0))
    with pytest.raises(ValueError, match="layers"):
        registry.get("filter", "aa_rnn").factory(layers=3, weights=str(path))
    with np.load(path) as data:
        stored = {k: np.array(data[k]) for k in data.files}
    stored["head"] = stored["head"] * 2.0
    np.savez(tmp_path / "tampered.npz", **stored)
    with pytest.raises(WeightsError, match="checksum"):
        load_weights(tmp_path / "tampered.npz")
    meta = json.loads(str(stored["meta"]))
    meta["format_version"] = 99
    stored["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "future.npz", **stored)
    with pytest.raises(WeightsError, match="format version"):
        load_weights(tmp_path / "future.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(WeightsError, match="corrupted"):
        load_weights(tmp_path / "junk.npz")
    with pytest.raises(WeightsError, match="not found"):
        load_weights(tmp_path / "missing.npz")


def test_spec_declares_the_task_and_the_trainer(registry):
    spec = registry.get("filter", "aa_rnn")
    assert spec.tasks == {"antialias"} and spec.temporal and spec.trainer is not None
    assert {"color", "normal", "depth", "motion"} <= spec.requires


# An independent float64 NumPy computation of the network's step (loops over the 3x3 taps, no
# PyTorch), from the definitions in plugins/filters/aa_rnn/network.py's docstring.

def _np_pad(x, mode):
    return np.pad(x, ((0, 0), (1, 1), (1, 1)), mode="edge" if mode == "replicate" else "constant")


def _np_windows(x, mode):
    """The nine 3x3-shifted copies of (C, H, W) ``x``: taps[dy + 1][dx + 1][c, i, j] = x[c, i + dy, j + dx]."""
    p = _np_pad(x, mode)
    h, w = x.shape[1:]
    return [[p[:, 1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dx in (-1, 0, 1)] for dy in (-1, 0, 1)]


def _np_mean3(x):
    return sum(t for row in _np_windows(x, "replicate") for t in row) / 9.0


def _np_max3(x):
    return np.max([t for row in _np_windows(x, "replicate") for t in row], axis=0)


def _np_conv3x3(x, weight):
    """Zero-padded 3x3 cross-correlation without bias: out[o] = sum_{c,dy,dx} w[o,c,dy,dx] x[c, i+dy-1, j+dx-1]."""
    taps = _np_windows(x, "zeros")
    out = np.zeros((weight.shape[0],) + x.shape[1:])
    for ky in range(3):
        for kx in range(3):
            out += np.einsum("oc,chw->ohw", weight[:, :, ky, kx].astype(np.float64), taps[ky][kx])
    return out


def _np_bilinear(img, x, y):
    """``img`` (C, H, W) at image points (x, y), coordinates clamped to the outer pixel centres."""
    h, w = img.shape[1:]
    x = np.clip(x, 0.0, w - 1.0)
    y = np.clip(y, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(int), w - 1)
    y0 = np.minimum(np.floor(y).astype(int), h - 1)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = x - x0, y - y0
    return (img[:, y0, x0] * (1 - fx) * (1 - fy) + img[:, y0, x1] * fx * (1 - fy)
            + img[:, y1, x0] * (1 - fx) * fy + img[:, y1, x1] * fx * fy)


def _np_step(frame, state, arrays, layers):
    u_max = 1.0 - 2.0**-20
    color = np.maximum(np.asarray(frame["color"], np.float64), 0.0).transpose(2, 0, 1)
    u = color / (1.0 + color)
    normal = np.asarray(frame["normal"], np.float64).transpose(2, 0, 1)
    depth = np.asarray(frame["depth"], np.float64)
    surface = np.isfinite(depth) & (depth > 0)
    z = np.where(surface, 1.0 / np.where(surface, depth, 1.0), 0.0)[None]
    motion = np.asarray(frame["motion"], np.float64)
    h, w = depth.shape
    x = np.arange(w)[None, :] + motion[..., 0] - frame.meta.jitter[0] * surface
    y = np.arange(h)[:, None] + motion[..., 1] - frame.meta.jitter[1] * surface
    if state is None:
        history = u
    else:
        inside = (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
        history = np.where(inside[None], _np_bilinear(state, x, y), u)
    g = np.maximum(_np_max3(u.max(axis=0, keepdims=True)), history.max(axis=0, keepdims=True))
    inv_g = np.where(g > 1e-8, 1.0 / np.maximum(g, 1e-8), 0.0)
    mz = _np_mean3(z)
    dz = np.where(mz > 1e-12, (z - mz) / np.maximum(mz, 1e-12), 0.0)
    f = np.concatenate([(u - _np_mean3(u)) * inv_g, (history - u) * inv_g, normal - _np_mean3(normal), dz])
    for k in range(layers):
        f = np.maximum(_np_conv3x3(f, arrays[f"conv{k}"]), 0.0)
    out = np.clip(u + g * _np_conv3x3(f, arrays["head"]), 0.0, u_max)
    return out


def test_forward_pass_equals_an_independent_numpy_computation(registry):
    arrays, _ = load_weights(shipped_weights(DEFAULT_LAYERS))
    filt = registry.get("filter", "aa_rnn").factory(backend="cpu")
    frames = _frames(4, h=9, w=13, seed=5)
    state = None
    for frame in frames:
        out = filt(frame)
        state = _np_step(frame, state, arrays, DEFAULT_LAYERS)
        # in the tone-mapped domain u = x / (1 + x), where float32 rounding is uniform
        np.testing.assert_allclose(out / (1.0 + out), state.transpose(1, 2, 0), atol=1e-5)
    aliased = frames[-1]["color"] / (1.0 + frames[-1]["color"])
    assert np.abs(state.transpose(1, 2, 0) - aliased).max() > 1e-2, "the network changes the image"


def test_numpy_convolution_is_pytorchs_conv2d_on_a_small_input():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(4, 5, 6))
    weight = rng.normal(size=(3, 4, 3, 3)).astype(np.float32)
    expected = torch.nn.functional.conv2d(torch.from_numpy(x)[None], torch.from_numpy(weight).double(), padding=1)
    np.testing.assert_allclose(_np_conv3x3(x, weight), expected[0].numpy(), atol=1e-12)
    # one output by hand: the corner pixel sees only the 2x2 taps inside the image
    corner = sum(weight[1, c, ky, kx] * x[c, ky - 1, kx - 1] for c in range(4) for ky in (1, 2) for kx in (1, 2))
    assert abs(_np_conv3x3(x, weight)[1, 0, 0] - corner) < 1e-12
