"""Tests of the ``eaw`` filter: a NumPy oracle, properties, edges, quality, numerics."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from harness import CHANNELS, Frame, FrameMeta, kernels, load_plugins
from plugins.filters.eaw import make_filter
from plugins.filters.eaw.layout import padded_stride
from plugins.filters.eaw.params import DEFAULTS, EAWParams

ROOT = Path(__file__).resolve().parents[1]
B3 = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
LUMA = np.array([0.2126, 0.7152, 0.0722])


# ---------------------------------------------------------------- the oracle


def _shift(a, dy, dx):
    """``a[y + dy, x + dx]`` with zeros outside, and the inside mask."""
    h, w = a.shape[:2]
    ys, xs = np.arange(h) + dy, np.arange(w) + dx
    iy, ix = (ys >= 0) & (ys < h), (xs >= 0) & (xs < w)
    inside = iy[:, None] & ix[None, :]
    out = a[np.clip(ys, 0, h - 1)][:, np.clip(xs, 0, w - 1)]
    out = np.where(inside.reshape(inside.shape + (1,) * (a.ndim - 2)), out, 0)
    return out, inside


def oracle(channels: dict, **params) -> np.ndarray:
    """Slow float64 EAW, written from the equations (ALGORITHMS.md + the plugin's README)."""
    p = EAWParams.from_kwargs(**params)
    color = channels["color"].astype(np.float64)
    normal = channels["normal"].astype(np.float64)
    position = channels["position"].astype(np.float64)
    surface = np.any(normal != 0, axis=2)
    if "object_id" in channels:
        surface &= channels["object_id"] != -1
    if "depth" in channels:
        surface &= np.isfinite(channels["depth"])
    active = surface.copy()
    if "variance" in channels:
        active &= np.any(channels["variance"] != 0, axis=2)

    lum = color @ LUMA
    lum32 = channels["color"] @ LUMA.astype(np.float32)
    positive = surface & (lum32 >= np.finfo(np.float32).tiny) & np.isfinite(lum32)
    scale = math.exp(np.mean(np.log(lum[positive]))) if p.color_scale == "logmean" and positive.any() else 1.0
    lo = position[surface].min(axis=0) if surface.any() else np.zeros(3)
    hi = position[surface].max(axis=0) if surface.any() else np.zeros(3)
    unit = np.linalg.norm(hi - lo) if p.position_units == "scene" and np.linalg.norm(hi - lo) > 0 else 1.0
    x = (position - lo) / unit

    c = color / scale
    for i, f in enumerate(p.rt_factors()):
        step = 2**i
        inv = lambda s: 0.0 if math.isinf(s) else 1.0 / (s * s)  # noqa: E731
        a_c, a_n, a_x = inv(p.sigma_rt * f), inv(p.sigma_n) / step**2, inv(p.sigma_x)
        num = np.zeros_like(c)
        den = np.zeros(c.shape[:2])
        for ky in range(5):
            for kx in range(5):
                dy, dx = (ky - 2) * step, (kx - 2) * step
                cq, inside = _shift(c, dy, dx)
                nq, _ = _shift(normal, dy, dx)
                xq, _ = _shift(x, dy, dx)
                sq, _ = _shift(surface, dy, dx)
                dist = (a_c * np.sum((cq - c) ** 2, axis=2) + a_n * np.sum((nq - normal) ** 2, axis=2)
                        + a_x * np.sum((xq - x) ** 2, axis=2))
                w = B3[ky] * B3[kx] * np.exp(-dist) * (inside & sq)
                num += w[..., None] * cq
                den += w
        c = np.where(active[..., None], num / np.where(den > 0, den, 1.0)[..., None], c)
    return np.where(active[..., None], c * scale, color)


# ---------------------------------------------------------------- inputs


def scene_channels(h: int, w: int, seed: int = 0, *, sky_rows: int = 0, extra=()) -> dict:
    """Two surfaces meeting at a crease (normal and depth step) plus optional sky rows."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    right = xx >= w // 2
    normal = np.where(right[..., None], [0.0, 0.6, 0.8], [0.0, 0.0, 1.0])
    position = np.stack([xx * 0.1, yy * 0.1, np.where(right, 0.5 + 0.02 * xx, 0.0)], axis=-1)
    base = np.where(right[..., None], [0.9, 0.7, 0.5], [0.2, 0.25, 0.3])
    color = base * rng.exponential(1.0, (h, w, 1)) + 0.05 * rng.random((h, w, 3))
    sky = yy < sky_rows
    normal[sky] = 0.0
    position[sky] = 0.0
    color[sky] = [0.4, 0.6, 1.0]
    ch = {
        "color": color.astype(np.float32),
        "normal": normal.astype(np.float32),
        "position": position.astype(np.float32),
    }
    if "variance" in extra:
        var = (0.1 * base * base * np.ones((h, w, 1))).astype(np.float32)
        var[sky] = 0.0
        var[h - 1, :] = 0.0  # a noise-free surface row
        ch["variance"] = var
    if "object_id" in extra:
        ch["object_id"] = np.where(sky, -1, right.astype(np.int32)).astype(np.int32)
    if "depth" in extra:
        ch["depth"] = np.where(sky, np.inf, 1.0 + yy).astype(np.float32)
    return ch


def frame_of(channels: dict) -> Frame:
    return Frame(channels, FrameMeta(scene="test"))


def rel_err(a, b) -> float:
    return float(np.max(np.abs(a.astype(np.float64) - b)) / max(np.max(np.abs(b)), 1e-30))


# ---------------------------------------------------------------- oracle agreement

ORACLE_CASES = [
    ((17, 23), dict(iterations=3), ()),
    ((20, 16), dict(iterations=2, sigma_rt=0.8, sigma_n=0.2, sigma_x=0.05), ("variance",)),
    ((21, 19), dict(iterations=3, sigma_rt=8.0, sigma_rt_schedule=(1.0, 0.7, 0.4)), ("object_id", "depth")),
    ((15, 18), dict(iterations=2, sigma_rt=math.inf, color_scale="none", position_units="world", sigma_x=0.3), ()),
    ((40, 36), dict(), ("variance", "depth")),
]


@pytest.mark.parametrize("shape,params,extra", ORACLE_CASES)
def test_cpu_matches_oracle(shape, params, extra):
    ch = scene_channels(*shape, seed=sum(shape), sky_rows=3, extra=extra)
    want = oracle(ch, **params)
    got = make_filter("cpu", **params)(frame_of(ch))
    assert got.dtype == np.float32 and got.shape == ch["color"].shape
    assert rel_err(got, want) < 1e-5


@pytest.mark.slow
def test_cuda_simulator_matches_oracle():
    """The CUDA kernels under NUMBA_ENABLE_CUDASIM=1 (a subprocess: the setting must precede
    the first import of numba.cuda) against the oracle."""
    script = textwrap.dedent(
        """
        import numpy as np
        import tests.test_eaw as t
        from plugins.filters.eaw import make_filter
        for shape, params, extra in [((12, 10), dict(iterations=2, sigma_rt=1.0), ("variance",)),
                                     ((9, 14), dict(iterations=3, sigma_rt_schedule=0.7), ("object_id",))]:
            ch = t.scene_channels(*shape, seed=3, sky_rows=2, extra=extra)
            got = make_filter("cuda", **params)(t.frame_of(ch))
            err = t.rel_err(got, t.oracle(ch, **params))
            assert err < 1e-5, err
        # bad input: a NaN normal, an infinite position, a colour of 3e38; CUDA equals the CPU
        ch = t.scene_channels(11, 13, seed=4, sky_rows=2)
        ch["normal"][4, 5, 0] = np.nan
        ch["position"][6, 2, 2] = np.inf
        ch["color"][7, 8] = 3e38
        got = make_filter("cuda", iterations=3)(t.frame_of(ch))
        want = make_filter("cpu", iterations=3)(t.frame_of(ch))
        assert np.all(np.isfinite(got))
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        print("ok")
        """
    )
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1", "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0 and "ok" in res.stdout, res.stdout + res.stderr


# ---------------------------------------------------------------- properties


def test_constant_image_stays_exactly_constant():
    ch = scene_channels(24, 30, sky_rows=4)
    ch["color"] = np.full_like(ch["color"], 0.37)
    out = make_filter("cpu")(frame_of(ch))
    assert np.array_equal(out, ch["color"])


def test_no_bleeding_across_normal_discontinuity():
    h, w = 32, 48
    ch = scene_channels(h, w, seed=5)
    filt = make_filter("cpu")(frame_of(ch))
    blur = make_filter("cpu", sigma_rt=math.inf, sigma_n=math.inf, sigma_x=math.inf)(frame_of(ch))
    left = slice(w // 2 - 3, w // 2)  # the three columns next to the crease, left side
    truth = np.array([0.2, 0.25, 0.3]) + 0.025  # mean of base * Exp(1) + U(0, 0.05)
    leak = np.abs(filt[:, left].mean(axis=(0, 1)) - truth).max()
    leak_blur = np.abs(blur[:, left].mean(axis=(0, 1)) - truth).max()
    assert leak_blur > 0.1  # the plain à-trous blur does bleed
    assert leak < 0.2 * leak_blur


def test_background_and_noise_free_pixels_are_untouched():
    ch = scene_channels(20, 24, seed=2, sky_rows=5, extra=("variance",))
    out = make_filter("cpu")(frame_of(ch))
    sky = np.all(ch["normal"] == 0, axis=2)
    still = np.all(ch["variance"] == 0, axis=2)
    assert np.array_equal(out[sky | still], ch["color"][sky | still])
    assert not np.array_equal(out[~(sky | still)], ch["color"][~(sky | still)])


def test_synthetic_renderer_rmse_falls_well_below_noisy():
    reg = load_plugins()
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes["synthetic-edges"].factory()
    res = (96, 72)
    frame = renderer.render(scene, 0, spp=1, seed=0, channels=frozenset(CHANNELS), resolution=res)
    ref = renderer.reference(scene, 0, spp=0, seed=0, resolution=res)
    out = make_filter("cpu")(frame)
    rmse = lambda a: float(np.sqrt(np.mean((a - ref) ** 2)))  # noqa: E731
    assert rmse(out) < 0.45 * rmse(frame["color"])


def test_input_unmodified_and_deterministic():
    ch = scene_channels(18, 22, seed=4, sky_rows=2)
    frame = frame_of(ch)
    before = {k: v.copy() for k, v in ch.items()}
    f = make_filter("cpu")
    a, b = f(frame), f(frame)
    assert np.array_equal(a, b)
    assert all(np.array_equal(frame[k], before[k]) for k in before)
    assert set(f.stage_ms) == {"prepare", "atrous"}


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (9, 1), (3, 5), (33, 17)])
def test_any_size(shape):
    ch = scene_channels(*shape, seed=1)
    out = make_filter("cpu", iterations=3)(frame_of(ch))
    assert out.shape == (*shape, 3) and np.all(np.isfinite(out))
    assert rel_err(out, oracle(ch, iterations=3)) < 1e-5


@pytest.mark.parametrize("kind", ["firefly_1e30", "all_1e30", "tiny_1e-30", "float16_max", "firefly_1e6", "zero"])
@pytest.mark.parametrize("color_scale", ["logmean", "none"])
def test_extreme_values_stay_finite(kind, color_scale):
    ch = scene_channels(16, 20, seed=6, sky_rows=2)
    c = ch["color"]
    if kind == "firefly_1e30":
        c[5, 7] = 1e30
        c[9, 15] = [1e30, 0.0, 1e30]
    elif kind == "all_1e30":
        c *= np.float32(1e30)
    elif kind == "tiny_1e-30":
        c *= np.float32(1e-30)
    elif kind == "float16_max":
        c[:] = np.where(c > 0.5, 65504.0, 6e-8)
    elif kind == "firefly_1e6":
        c[::4, ::3] = 1e6
    else:
        c[:] = 0.0
    out = make_filter("cpu", color_scale=color_scale)(frame_of(ch))
    assert np.all(np.isfinite(out))
    if kind == "zero":
        assert np.all(out == 0.0)
    if kind in ("all_1e30", "tiny_1e-30") and color_scale == "logmean":
        # exposure invariance: scaling the input scales the output
        base = make_filter("cpu", color_scale=color_scale)(frame_of(scene_channels(16, 20, seed=6, sky_rows=2)))
        factor = 1e30 if kind == "all_1e30" else 1e-30
        assert rel_err(out / np.float32(factor), base.astype(np.float64)) < 1e-5


@pytest.mark.parametrize("channel,value", [("normal", np.nan), ("normal", np.inf), ("position", np.nan),
                                           ("position", -np.inf)])
def test_nonfinite_guide_makes_a_background_pixel(channel, value):
    """A pixel with a NaN or infinite normal or position is background, exactly as a pixel with
    a zero normal (the harness's convention): passed through, never a tap, outside the scales."""
    ch = scene_channels(24, 30, seed=7, sky_rows=3)
    bad = {k: v.copy() for k, v in ch.items()}
    bad[channel][9, 11, 1] = value
    zero = {k: v.copy() for k, v in ch.items()}
    zero["normal"][9, 11] = 0.0
    out = make_filter("cpu")(frame_of(bad))
    assert np.array_equal(out, make_filter("cpu")(frame_of(zero)))
    assert np.array_equal(out[9, 11], ch["color"][9, 11])


def test_one_huge_colour_value_stays_local():
    """A colour of 3e38 (finite) used to turn the whole image into NaN; now it is kept as it is
    and its neighbours ignore it (its colour distance to them is beyond every weight)."""
    ch = scene_channels(24, 30, seed=8, sky_rows=2)
    base = make_filter("cpu")(frame_of(ch))
    ch["color"][10, 12] = 3e38
    out = make_filter("cpu")(frame_of(ch))
    assert np.all(np.isfinite(out))
    assert out[10, 12, 0] == np.float32(3e38)
    far = np.ones(out.shape[:2], bool)
    far[10 - 3:10 + 4, 12 - 3:12 + 4] = False  # the colour scale moved a little: compare loosely
    assert rel_err(out[far], base[far].astype(np.float64)) < 0.2


# ---------------------------------------------------------------- parameters and registration


def test_parameters_are_validated():
    with pytest.raises(TypeError, match="sigma_q"):
        make_filter("cpu", sigma_q=1.0)
    with pytest.raises(ValueError, match="iterations"):
        make_filter("cpu", iterations=0)
    with pytest.raises(ValueError, match="sigma_n"):
        make_filter("cpu", sigma_n=-1.0)
    with pytest.raises(ValueError, match="sigma_rt_schedule"):
        make_filter("cpu", iterations=3, sigma_rt_schedule=(1.0, 0.5))
    with pytest.raises(ValueError, match="color_scale"):
        make_filter("cpu", color_scale="linear")
    with pytest.raises(ValueError, match="backend"):
        make_filter("metal")


def test_schedule_and_coefficients():
    p = EAWParams(iterations=3, sigma_rt=2.0, sigma_n=0.5, sigma_x=math.inf)
    assert p.rt_factors() == (1.0, 0.5, 0.25)
    coef = p.coefficients()
    np.testing.assert_allclose(coef[:, 0], [1 / 4, 1, 4], rtol=1e-6)
    np.testing.assert_allclose(coef[:, 1], [4, 1, 1 / 4], rtol=1e-6)
    assert np.all(coef[:, 2] == 0.0)


def test_registered_by_entry_point():
    spec = load_plugins().filters["eaw"]
    assert spec.requires == {"color", "normal"} and spec.full_guides == {"normal", "position"}
    assert set(spec.backends) == {"cpu", "cuda"} and not spec.temporal
    assert dict(spec.params) == DEFAULTS


@pytest.mark.parametrize("width,halo", [(1280, 32), (1920, 32), (1, 2), (100, 8), (1296, 0)])
def test_padded_stride_avoids_power_of_two_aliasing(width, halo):
    s = padded_stride(width, halo)
    assert s >= width + 2 * halo and s % 32 == 16 and s < width + 2 * halo + 32


def test_parallel_path_matches_oracle():
    """Images of 256x256 pixels and more run on all threads (smaller ones on one)."""
    h, w = 257, 256
    assert h * w >= kernels.SERIAL_MAX_PIXELS
    ch = scene_channels(h, w, seed=9, sky_rows=40, extra=("variance",))
    params = dict(iterations=3, sigma_rt=4.0)
    assert rel_err(make_filter("cpu", **params)(frame_of(ch)), oracle(ch, **params)) < 1e-5


@pytest.mark.parametrize("parts", [1, 2, 3, 5, 8])
def test_output_does_not_depend_on_the_cut_into_parts(monkeypatch, parts):
    """A part that starts inside a class of rows recomputes the weights of the two rows above
    it: any cut of the rows into parts (here more parts than threads, and at hole spacings up
    to 16 on 257 rows) gives the same image bit for bit."""
    from plugins.filters.eaw import cpu

    ch = scene_channels(257, 256, seed=4, sky_rows=30, extra=("variance",))
    reference = make_filter("cpu", iterations=5)(frame_of(ch))
    monkeypatch.setattr(cpu, "get_num_threads", lambda: parts)
    np.testing.assert_array_equal(make_filter("cpu", iterations=5)(frame_of(ch)), reference)


def _prepared(h, w, sky_rows):
    from plugins.filters.eaw.layout import Buffers, prepare

    b = Buffers(h, w, 32)
    prepare(frame_of(scene_channels(h, w, seed=1, sky_rows=sky_rows, extra=("variance",))),
            EAWParams.from_kwargs(iterations=5), b)
    return b


@pytest.mark.parametrize("step", [1, 4, 16])
def test_parts_have_equal_work_with_their_ring_refill(step):
    """The rows go class by class of ``y mod step``; a part that starts inside a class also
    computes 2 rows of weights: counted in, the estimated work of the parts is equal to within
    a row's."""
    from plugins.filters.eaw import cpu

    h, w = 720, 64
    b = _prepared(h, w, 100)
    lengths = np.where(np.arange(8)[None, :] < b.run_count[:, None], b.runs[:, :, 1] - b.runs[:, :, 0], 0)
    weights = 2.0 * w * (b.row_surface != 0)
    row_cost = weights + lengths.sum(axis=1) + 0.05 * w
    for parts in (2, 3, 4):
        order, starts = cpu.balanced_parts(b, parts, step)
        np.testing.assert_array_equal(order, np.concatenate([np.arange(r, h, step) for r in range(step)]))
        assert starts[0] == 0 and starts[-1] == h and np.all(np.diff(starts) >= 0)
        work = []
        for s, e in zip(starts[:-1], starts[1:]):
            refill = sum(weights[order[s] - k * step] for k in (1, 2) if s < h and order[s] - k * step >= 0)
            work.append(row_cost[order[s:e]].sum() + refill)
        assert max(work) - min(work) <= 2 * row_cost.max() + 2 * 2 * w, (parts, work)


def test_a_cut_between_classes_is_preferred():
    """With as many classes as parts and rows of equal work, each part is one class: no part
    recomputes weights another computes."""
    from plugins.filters.eaw import cpu

    b = _prepared(64, 48, 0)
    for step in (2, 4):
        order, starts = cpu.balanced_parts(b, step, step)
        np.testing.assert_array_equal(starts, np.arange(step + 1) * (64 // step))
        assert np.all(order[starts[:-1]] < step)
