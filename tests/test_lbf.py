"""Tests of the ``lbf`` filter plugin: Numba vs PyTorch, weights file, training, CUDA simulator."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from harness import CHANNELS, Frame, FrameMeta, load_plugins
from plugins.filters.lbf import cpu as CPU
from plugins.filters.lbf import features as FE
from plugins.filters.lbf import kernels as K
from plugins.filters.lbf.denoiser import LBFFilter
from plugins.filters.lbf.weights import (
    DEFAULT_WEIGHTS,
    FORMAT_VERSION,
    LBFWeights,
    WeightsError,
    load_weights,
    save_weights,
)

torch = pytest.importorskip("torch")
TR = pytest.importorskip("plugins.filters.lbf.torch_ref")

ROOT = Path(__file__).resolve().parents[1]
FULL = {"color", "normal", "albedo", "position", "variance"}  # the paper's inputs


def cpu_stages(inputs: FE.Inputs, radius: int = 5, model: LBFWeights | None = None):
    """The CPU pipeline's output and its kept intermediates (variance, sig, features, params)."""
    d = CPU.Denoiser(model or load_weights())
    d.keep = True
    out, _ = d(inputs, radius)
    return out, d.last


def extract_features(inputs: FE.Inputs):
    last = cpu_stages(inputs)[1]
    return last["variance"], last["sig"], last["features"]


def random_frame(h, w, seed=0, visibility=False, spp=False, scale=1.0, variance=True) -> Frame:
    """A frame with piecewise-constant G-buffer regions, a background corner and noisy colour.

    ``variance=False`` zeroes the variance channel (as a 1-spp path tracer leaves it).
    """
    variance_on = 1.0 if variance else 0.0
    rng = np.random.default_rng(seed)
    region = (np.arange(w)[None, :] * 3 // max(w, 1) + (np.arange(h)[:, None] * 2 // max(h, 1)) * 3)
    normals = rng.normal(size=(6, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normal = normals[region]
    albedo = rng.uniform(0.1, 0.9, (6, 3))[region]
    position = rng.normal(size=(h, w, 3)) * 0.1 + region[..., None] * 0.5
    fg = np.ones((h, w), bool)
    fg[: max(h // 4, 0), : max(w // 4, 0)] = False
    normal[~fg] = 0
    albedo[~fg] = 0
    position[~fg] = 0
    clean = albedo * rng.uniform(0.2, 2.0, 6)[region][..., None] + (~fg)[..., None] * 0.7
    var = (0.3 * clean) ** 2 * fg[..., None]
    color = clean + rng.normal(size=(h, w, 3)) * np.sqrt(var)
    ch = {
        "color": (color * scale).astype(np.float32),
        "variance": np.minimum(var * scale * scale * variance_on, 1e38).astype(np.float32),
        "normal": normal.astype(np.float32),
        "albedo": albedo.astype(np.float32),
        "position": position.astype(np.float32),
    }
    if visibility:
        ch["visibility"] = (rng.uniform(size=(h, w)) > 0.3).astype(np.float32) * fg
    if spp:
        ch["spp"] = rng.integers(1, 5, (h, w)).astype(np.int32)
    return Frame(ch, FrameMeta(scene="lbf-test"))


def synthetic_frame(width=40, height=30, seed=0):
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes["synthetic-edges"].factory()
    size = (width, height)
    channels = frozenset(CHANNELS)
    frame = renderer.render(scene, 0, spp=1, seed=seed, channels=channels, resolution=size)
    return frame, renderer.reference(scene, 0, resolution=size)


def torch_inputs(inputs: FE.Inputs):
    def t(a):
        return torch.from_numpy(np.array(a))

    return (t(inputs.color), t(inputs.variance), t(inputs.position), t(inputs.normal),
            t(inputs.albedo), t(inputs.vis) if inputs.has_vis else None,
            t(inputs.spp) if inputs.has_spp else None)


def t64(a):
    return torch.from_numpy(np.array(a, np.float64))


def torch_mlp(feat, model: LBFWeights):
    feat = feat if isinstance(feat, torch.Tensor) else t64(feat)
    arrays = (model.mean, model.inv_std, model.w1, model.b1, model.w2, model.b2)
    return TR.mlp(feat, *(t64(a) for a in arrays))


def torch_pipeline(inputs: FE.Inputs, model: LBFWeights, radius: int) -> np.ndarray:
    """The whole filter in float64 PyTorch: the reference of the Numba inference."""
    var, sig, feat = TR.features(*torch_inputs(inputs))
    params = torch_mlp(feat, model)
    t = t64
    return TR.cross_bilateral(t(inputs.color), var, sig, params, radius).numpy()


def relmse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref * ref + 0.01)))


# --- Numba inference against the PyTorch implementation ---------------------------------------

@pytest.mark.parametrize(
    "make",
    [
        lambda: synthetic_frame(40, 30)[0],
        lambda: random_frame(13, 7, seed=1, visibility=True, spp=True),
        lambda: random_frame(1, 9, seed=2),
        lambda: random_frame(1, 1, seed=3),
        lambda: random_frame(11, 14, seed=4, variance=False),
    ],
    ids=["synthetic", "random-odd", "row", "pixel", "no-variance"],
)
def test_features_match_torch(make):
    inputs = FE.gather_inputs(make())
    var, sig, feat = extract_features(inputs)
    var_t, sig_t, feat_t = TR.features(*torch_inputs(inputs))
    np.testing.assert_allclose(var, var_t.numpy(), rtol=1e-6, atol=1e-12)
    assert feat.shape == inputs.shape + (len(FE.FEATURE_NAMES),)
    np.testing.assert_allclose(sig, sig_t.numpy(), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(feat, feat_t.numpy(), rtol=1e-5, atol=1e-5)


def test_features_analytic_values():
    """A constant frame has zero deviations, gradients and noise, and known pixel statistics."""
    h, w = 9, 11
    ch = {
        "color": np.full((h, w, 3), np.e - 1, np.float32),
        "variance": np.full((h, w, 3), 4.0 * np.e**2, np.float32),
        "normal": np.tile(np.float32([0, 1, 0]), (h, w, 1)),
        "albedo": np.full((h, w, 3), 0.5, np.float32),
        "position": np.zeros((h, w, 3), np.float32),
    }
    _, _, feat = extract_features(FE.gather_inputs(Frame(ch)))
    named = dict(zip(FE.FEATURE_NAMES, np.moveaxis(feat, -1, 0), strict=True))
    for prefix in ("std7_", "std3_", "mad3_", "grad_", "noise_"):
        for g in FE.GROUPS:
            np.testing.assert_allclose(named[prefix + g], 0.0, atol=1e-6)
    np.testing.assert_allclose(named["pixel_color"], 1.0, rtol=1e-6)  # log1p(e - 1)
    np.testing.assert_allclose(named["sample_std_color"], 2.0, rtol=1e-5)  # sqrt(4 e^2) / e
    np.testing.assert_allclose(named["pixel_visibility"], 1.0)  # stand-in: all foreground
    np.testing.assert_allclose(named["inv_spp"], 1.0)


def test_visibility_standin_is_foreground_mask():
    frame = random_frame(8, 12, seed=4, visibility=True)
    fg = (frame["normal"] != 0).any(-1)
    _, sig_auto, _ = extract_features(FE.gather_inputs(frame, "auto"))
    _, sig_stand, _ = extract_features(FE.gather_inputs(frame, "standin"))
    np.testing.assert_array_equal(sig_auto[..., 12], frame["visibility"])
    np.testing.assert_array_equal(sig_stand[..., 12], fg.astype(np.float32))


def test_network_and_filter_match_torch():
    model = load_weights()
    frame = random_frame(15, 17, seed=5, visibility=True)
    inputs = FE.gather_inputs(frame)
    out, last = cpu_stages(inputs, 4, model)
    var, sig, feat, params = last["variance"], last["sig"], last["features"], last["params"]
    params_t = torch_mlp(feat, model)
    t = t64
    np.testing.assert_allclose(params, params_t.numpy(), rtol=1e-5, atol=1e-12)
    assert np.all(params > 0)
    out_t = TR.cross_bilateral(t(inputs.color), t(var), t(sig), t(params), 4)
    np.testing.assert_allclose(out, out_t.numpy(), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("radius", [0, 2, 5])
def test_end_to_end_matches_torch(radius):
    frame, _ = synthetic_frame(24, 18, seed=3)
    filt = LBFFilter(radius=radius)
    out = filt(frame)
    ref = torch_pipeline(FE.gather_inputs(frame), filt.model, radius)
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-5)
    assert set(filt.stage_ms) == {"signals", "network", "bilateral"}
    if radius == 0:
        np.testing.assert_array_equal(out, frame["color"])


def test_filter_gradient_wrt_bandwidths():
    """The PyTorch filter is differentiable in its bandwidths (autograd = finite differences)."""
    frame = random_frame(3, 4, seed=6)
    inputs = FE.gather_inputs(frame)
    _, sig, _ = TR.features(*torch_inputs(inputs))
    params = torch.full((3, 4, 6), 0.05, dtype=torch.float64, requires_grad=True)
    color, var = torch_inputs(inputs)[:2]
    loss = lambda p: TR.cross_bilateral(color, var, sig, p, 1).sum()  # noqa: E731
    assert torch.autograd.gradcheck(loss, (params,))


# --- behaviour of the filter ---------------------------------------------------------------------

def test_shipped_weights_denoise_benchmark_scene():
    frame, ref = synthetic_frame(64, 48, seed=11)
    out = LBFFilter()(frame)
    assert relmse(out, ref) < 0.5 * relmse(frame["color"], ref)
    meta = load_weights().meta
    assert len(meta["training_data_hash"]) == 64 and meta["seed"] == 0
    assert meta["heldout_relmse"]["final"] < meta["heldout_relmse"]["initial"]


def test_properties():
    filt = LBFFilter()
    frame = random_frame(10, 13, seed=7)
    color = frame["color"].copy()
    a, b = filt(frame), filt(frame)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(frame["color"], color)
    assert a.dtype == np.float32 and a.shape == (10, 13, 3)
    const = frame.replace(color=np.full((10, 13, 3), 0.37, np.float32))
    np.testing.assert_allclose(filt(const), 0.37, rtol=1e-6)
    zeros = np.zeros((10, 13, 3), np.float32)
    zero = frame.replace(color=zeros, variance=zeros)
    np.testing.assert_array_equal(filt(zero), 0.0)
    for scale in (1e30, 1e-30, 6e4):
        out = filt(random_frame(9, 8, seed=8, scale=scale))
        assert np.all(np.isfinite(out))
    firefly = color.copy()
    firefly[5, 6] = 1e6
    assert np.all(np.isfinite(filt(frame.replace(color=firefly))))


def test_spec_and_parameters():
    reg = load_plugins()
    spec = reg.filters["lbf"]
    assert spec.requires == frozenset({"color", "normal", "albedo"})  # the others: degraded modes
    assert spec.optional == frozenset({"position", "variance", "depth", "visibility", "spp"})
    assert spec.full_guides == frozenset(FULL) - {"color"}
    assert spec.backends == ("cpu", "cuda") and spec.trainer is not None
    filt = spec.factory(backend="cpu", **spec.params)
    assert filt.radius == 5
    with pytest.raises(TypeError, match="bogus"):
        spec.factory(backend="cpu", bogus=1)
    with pytest.raises(ValueError, match="radius"):
        LBFFilter(radius=-1)
    with pytest.raises(ValueError, match="backend"):
        LBFFilter(backend="metal")
    with pytest.raises(ValueError, match="visibility"):
        LBFFilter(visibility="maybe")


# --- weights file ---------------------------------------------------------------------------------

def _rewrite(src: Path, dst: Path, **changes):
    with np.load(src) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    for key, value in changes.items():
        if key in arrays:
            arrays[key] = value
        else:
            meta[key] = value
    np.savez(dst, meta=np.array(json.dumps(meta)), **arrays)
    return dst


def test_weights_roundtrip(tmp_path):
    model = load_weights(DEFAULT_WEIGHTS)
    path = save_weights(model, tmp_path / "w.npz")
    again = load_weights(path)
    for name in ("w1", "b1", "w2", "b2", "mean", "std"):
        np.testing.assert_array_equal(getattr(again, name), getattr(model, name))
    assert again.meta["training_data_hash"] == model.meta["training_data_hash"]


def test_weights_errors(tmp_path):
    good = DEFAULT_WEIGHTS
    with pytest.raises(WeightsError, match="not found"):
        load_weights(tmp_path / "missing.npz")
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:300])
    with pytest.raises(WeightsError, match="corrupted"):
        load_weights(truncated)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a weights file" * 10)
    with pytest.raises(WeightsError, match="corrupted"):
        load_weights(garbage)
    altered = load_weights(good).w1.copy()
    altered[0, 0] += 1.0
    with pytest.raises(WeightsError, match="checksum"):
        load_weights(_rewrite(good, tmp_path / "altered.npz", w1=altered))
    with pytest.raises(WeightsError, match="format version"):
        load_weights(_rewrite(good, tmp_path / "version.npz", format_version=FORMAT_VERSION + 1))
    names = list(FE.FEATURE_NAMES)
    names[3], names[4] = names[4], names[3]
    with pytest.raises(WeightsError, match="feature list mismatch"):
        load_weights(_rewrite(good, tmp_path / "features.npz", feature_names=names))
    with pytest.raises(WeightsError, match="shape"):
        wide = np.zeros((12, K.N_FEATURES), np.float32)
        load_weights(_rewrite(good, tmp_path / "shape.npz", w1=wide))
    with pytest.raises(WeightsError):
        LBFFilter(weights=str(truncated))


# --- training -------------------------------------------------------------------------------------

@pytest.mark.slow
def test_training_data_excludes_benchmark_scenes_and_is_deterministic():
    from plugins.filters.lbf import train as T

    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    variants = [T._variant(rng_a, T.FULL) for _ in range(40)]
    assert all(v["layout"]["checker"] != T.BENCHMARK_CHECKER for v in variants)
    a = T.make_dataset(9, 2, T.QUICK)
    b = T.make_dataset(9, 2, T.QUICK)
    assert T.data_hash([a]) == T.data_hash([b])
    assert T._variant(rng_b, T.FULL) == variants[0]


@pytest.mark.slow
def test_quick_training_lowers_heldout_relmse(tmp_path):
    reg = load_plugins()
    path = reg.filters["lbf"].trainer(seed=1, output=tmp_path / "quick.npz", quick=True)
    model = load_weights(path)
    scores = model.meta["heldout_relmse"]
    assert scores["final"] < 0.8 * scores["initial"]
    assert scores["final"] < scores["noisy"]
    assert model.meta["quick"] is True and model.meta["seed"] == 1
    # the Numba inference with the new weights denoises an unseen frame
    frame, ref = synthetic_frame(48, 36, seed=21)
    out = LBFFilter(weights=str(path))(frame)
    assert relmse(out, ref) < relmse(frame["color"], ref)


# --- isolation and CUDA ---------------------------------------------------------------------------

def _run(code: str, **env) -> str:
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT,
                          capture_output=True, text=True, env={**os.environ, **env}, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


def test_inference_does_not_import_torch():
    out = _run("""
        import sys
        import numpy as np
        from harness import Frame
        from plugins.filters.lbf import LBFFilter
        rng = np.random.default_rng(0)
        ch = {k: rng.uniform(size=(5, 6, 3)).astype(np.float32)
              for k in ("color", "variance", "normal", "albedo", "position")}
        LBFFilter()(Frame(ch))
        print("torch" in sys.modules)
    """)
    assert out.strip() == "False"


@pytest.mark.slow
def test_cuda_simulator_matches_cpu():
    out = _run("""
        import numpy as np
        from tests.test_lbf import random_frame
        from plugins.filters.lbf import LBFFilter
        cpu, gpu = LBFFilter(backend="cpu", radius=3), LBFFilter(backend="cuda", radius=3)
        worst = 0.0
        frames = (random_frame(8, 9, seed=1, visibility=True, spp=True),
                  random_frame(5, 4, seed=3, variance=False), random_frame(1, 3, seed=2))
        for frame in frames:
            a, b = cpu(frame), gpu(frame)
            assert b.shape == a.shape and b.dtype == np.float32
            worst = max(worst, float(np.abs(a - b).max() / (np.abs(a).max() + 1e-6)))
        print(worst, sorted(gpu.stage_ms))
    """, NUMBA_ENABLE_CUDASIM="1")
    worst, stages = out.split(" ", 1)
    assert float(worst) < 1e-5
    assert "signals" in stages and "bilateral" in stages


_CACHE_PROBE = """
import numpy as np
from harness import load_plugins
reg = load_plugins()
spec = reg.get("filter", "lbf")
scene = reg.get("scene", "synthetic-moving").factory()
frame = reg.get("renderer", "synthetic").factory().render(
    scene, 0, spp=1, seed=0, channels=frozenset(spec.requires | spec.optional) - {"color"}, resolution=(48, 32))
print(np.asarray(spec.factory()(frame), np.float32).tobytes().hex())
"""


@pytest.mark.slow
def test_output_does_not_depend_on_the_numba_cache(tmp_path):
    """A fresh compile and a load from Numba's cache give the same bits (they differed by about
    1e-8 relative while the per-row helpers were compiled with ``fastmath``)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    runs = [subprocess.run([sys.executable, "-c", _CACHE_PROBE], env=env, capture_output=True, text=True,
                           check=True).stdout.strip() for _ in range(2)]
    assert any(tmp_path.rglob("*.nbi")), "the first run should have written the cache"
    assert runs[0] == runs[1]



def _per_pixel_network(sig, aux, hh, m):
    """The network stage pixel by pixel with the shared bodies (box7, combine, mlp): the CUDA
    backend's arithmetic, which the CPU's row kernels must reproduce bit for bit."""
    from numba import njit

    box7, combine, mlp = (njit(cache=False)(f) for f in (K.box7_px, K.combine_px, K.mlp_px))
    h, w = sig.shape[1:]
    params = np.empty((K.N_OUT, h, w), np.float32)
    feats = np.empty((h, w, K.N_FEATURES), np.float32)
    col7, med, feat = np.empty(K.N_BOX7), np.empty(9), np.empty(K.N_FEATURES)
    z, hidden, out = np.empty(K.N_FEATURES), np.empty(K.N_HIDDEN), np.empty(K.N_OUT)
    for i in range(h):
        for j in range(w):
            box7(i, j, sig, aux, col7)
            combine(i, j, sig, aux, hh, col7, med, feat)
            feats[i, j] = feat
            mlp(feat, m.mean, m.inv_std, m.w1, m.b1, m.w2, m.b2, z, hidden, out)
            params[:, i, j] = out
    return feats, params


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (6, 1), (2, 2), (9, 13), (17, 40)])
def test_row_network_matches_per_pixel_bodies(shape):
    """The CPU's vectorised row kernels (features, median network, MLP) give the per-pixel
    bodies' features exactly and their bandwidths to float32 round-off (the sigmoid and softplus
    use :mod:`.vecmath`), borders, ties in the medians and extremes included."""
    h, w = shape
    rng = np.random.default_rng(h * 100 + w)
    sig = rng.normal(size=(K.N_SIG, h, w)).astype(np.float32)
    sig[:, rng.random((h, w)) < 0.2] = 0.0  # ties
    sig[3, 0, 0] = K.FEATURE_LIMIT
    aux = rng.uniform(0, 2, (h, w, 3)).astype(np.float32)
    hh = np.round(rng.uniform(0, 2, (h, w, 5)), 1).astype(np.float32)  # many ties
    m = load_weights()
    feats, params = _per_pixel_network(sig, aux, hh, m)
    got_p = np.empty_like(params)
    got_f = np.empty_like(feats)
    hp = np.ascontiguousarray(np.moveaxis(hh, -1, 0))  # the CPU keeps the details planar
    CPU._features_network(sig, aux, hp, hp.transpose(1, 2, 0), m.mean, m.inv_std, m.w1, m.b1,
                          m.w2, m.b2, got_p, got_f, True, 2)
    np.testing.assert_array_equal(got_f, feats)
    np.testing.assert_allclose(got_p, params, rtol=2.5e-7, atol=0)  # at most ~1 float32 ulp


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (6, 1), (2, 2), (9, 13), (17, 40)])
@pytest.mark.parametrize("has_vis, has_spp", [(False, False), (True, True)])
def test_row_signals_match_per_pixel_bodies(shape, has_vis, has_spp):
    """The CPU's row kernels of the signals stage (signals, colour and variance planes, Haar
    details) give the per-pixel bodies' values bit for bit, non-finite and extreme inputs
    included."""
    from numba import njit

    h, w = shape
    rng = np.random.default_rng(h * 100 + w + has_vis)
    bad = np.array([np.nan, np.inf, -np.inf, -1.0, 0.0, -0.0, 3e38, 1e-40], np.float32)

    def guide(scale):
        a = (rng.normal(size=(h, w, 3)) * scale).astype(np.float32)
        mask = rng.random((h, w, 3)) < 0.15
        a[mask] = rng.choice(bad, size=int(mask.sum()))
        return a

    color, variance, position, normal, albedo = (guide(s) for s in (2.0, 0.1, 5.0, 1.0, 0.5))
    normal[rng.random((h, w)) < 0.2] = 0.0  # background
    color[0, 0] = (np.nan, np.inf, -np.inf)
    variance[-1, -1] = (np.nan, np.inf, -1.0)
    vis = rng.uniform(-0.5, 1.5, (h, w)).astype(np.float32) if has_vis else np.zeros((1, 1), np.float32)
    if has_vis:
        vis[rng.random((h, w)) < 0.2] = np.nan
    spp = rng.integers(-2, 64, (h, w)).astype(np.int32) if has_spp else np.ones((1, 1), np.int32)
    args = (color, variance, position, normal, albedo, vis, has_vis, spp, has_spp, 0.25, -1.0,
            2.0, 0.5)
    want_sig = np.zeros((K.N_SIG, h, w), np.float32)
    want_aux = np.zeros((h, w, 3), np.float32)
    want_hh = np.zeros((h, w, 5), np.float32)
    signals, haar = njit(cache=False)(K.signals_px), njit(cache=False)(K.haar_px)
    for i in range(h):
        for j in range(w):
            signals(i, j, *args, want_sig, want_aux)
    for i in range(h):
        for j in range(w):
            haar(i, j, want_sig, want_hh)
    pad = 2
    sp = np.zeros((K.N_SIG, h, w + 2 * pad), np.float32)
    cp, vp = np.zeros((3, h, w + 2 * pad), np.float32), np.zeros((3, h, w + 2 * pad), np.float32)
    aux, peaks, hh = np.zeros((h, w, 3), np.float32), np.zeros(h), np.zeros((5, h, w), np.float32)
    CPU._signals(*args, sp[:, :, pad:pad + w], aux, pad, cp, vp, peaks, 2)
    CPU._haar(sp[:, :, pad:pad + w], hh, 2)
    assert sp[:, :, pad:pad + w].tobytes() == want_sig.tobytes()
    assert aux.tobytes() == want_aux.tobytes()
    assert np.moveaxis(hh, 0, -1).tobytes() == want_hh.tobytes()
    f32max = np.finfo(np.float32).max
    want_c = np.where(np.isnan(color), 0.0, np.clip(color, -f32max, f32max))
    np.testing.assert_array_equal(cp[:, :, pad:pad + w], np.moveaxis(want_c, -1, 0))
    want_v = np.where(variance > 0, np.minimum(variance, CPU.VAR_PLANE_MAX), 0.0)
    np.testing.assert_array_equal(vp[:, :, pad:pad + w], np.moveaxis(want_v, -1, 0))
    np.testing.assert_array_equal(peaks, np.abs(want_c).max(axis=(1, 2)))
    assert not sp[:, :, :pad].any() and not sp[:, :, pad + w:].any()  # padding untouched


def test_median_network_is_the_median():
    rng = np.random.default_rng(5)
    for _ in range(2000):
        x = np.round(rng.normal(size=9), 1) if rng.random() < 0.5 else rng.normal(size=9)
        assert CPU._median9(*x) == np.sort(x)[4]


def test_vectorised_exp_and_log1p_match_libm():
    """:mod:`.vecmath`'s ``exp(-y)`` on [0, 708] and ``log1p(t)`` on [0, 1] (tiny ``t``, where
    ``1 + t`` rounds, included) within a few float64 ulps of libm; ``exp`` clamps at 708."""
    import math

    from numba import njit

    from plugins.filters.lbf.vecmath import EXP_CLAMP, exp_neg64, log1p64

    @njit
    def both(y, t, e, l):
        for j in range(y.size):
            e[j] = exp_neg64(y[j])
        for j in range(t.size):
            l[j] = log1p64(t[j])

    rng = np.random.default_rng(3)
    y = np.concatenate([[0.0, 1e-300, 0.5 * math.log(2), 1.0, 700.0, 708.0],
                        rng.uniform(0, 708, 5000), rng.uniform(0, 2, 5000)])
    t = np.concatenate([[0.0, 1e-300, 1e-17, 2.0**-53, 1e-8, math.sqrt(2) - 1, 1.0],
                        rng.uniform(0, 1, 5000), 10.0 ** rng.uniform(-20, 0, 5005)])
    e, l = np.empty_like(y), np.empty_like(t)
    both(y, t, e, l)
    exp_ref = np.array([math.exp(-v) for v in y])
    log_ref = np.array([math.log1p(v) for v in t])
    assert np.max(np.abs(e - exp_ref) / exp_ref) < 1e-15
    nz = log_ref > 0
    assert np.max(np.abs(l[nz] - log_ref[nz]) / log_ref[nz]) < 1e-15 and np.all(l[~nz] == 0.0)
    out = np.empty(1)
    both(np.array([1000.0]), np.array([0.5]), out, np.empty(1))
    assert abs(out[0] / math.exp(-EXP_CLAMP) - 1.0) < 1e-15
