"""The ``eaw`` filter's preparation passes (``layout.survey``, ``layout.frame_scales``,
``layout.pack``) against straightforward NumPy / Python references written from the documented
semantics, on frames full of bad values (NaN, +-inf, 3e38, -0.0, denormals, zero normals),
background from every source, still pixels, and rows of runs with gaps around ``MIN_GAP`` and
more than ``MAX_RUNS`` runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from plugins.filters.eaw import layout
from plugins.filters.eaw.layout import ACTIVE, BACKGROUND, MAX_RUNS, MIN_GAP, STILL

F32 = np.float32
TINY = np.finfo(np.float32).tiny
LUMA32 = np.array(layout.LUMA, np.float32)


# ---------------------------------------------------------------- references


def reference_classes(ch: dict) -> np.ndarray:
    """BACKGROUND / STILL / ACTIVE per pixel, from the module docstring's rules."""
    n, p = ch["normal"], ch["position"]
    surface = np.any(n != 0, axis=2) & np.all(np.isfinite(n), axis=2) & np.all(np.isfinite(p), axis=2)
    if "object_id" in ch:
        surface &= ch["object_id"] != -1
    if "depth" in ch:
        surface &= np.isfinite(ch["depth"])
    state = np.where(surface, ACTIVE, BACKGROUND).astype(np.int8)
    if "variance" in ch:
        state[surface & np.all(ch["variance"] == 0, axis=2)] = STILL
    return state


def reference_rows(ch: dict, state: np.ndarray):
    """Per row: sum of log(L) and count over surface pixels with a finite L >= tiny; the box."""
    surface = state != BACKGROUND
    with np.errstate(invalid="ignore", over="ignore"):
        lum = ch["color"] @ LUMA32
    ok = surface & np.isfinite(lum) & (lum >= TINY)
    logs = np.where(ok, np.log(np.where(ok, lum, 1.0).astype(np.float64)), 0.0)
    p = ch["position"].astype(np.float64)
    lo = np.where(surface[..., None], p, np.inf).min(axis=1)
    hi = np.where(surface[..., None], p, -np.inf).max(axis=1)
    return logs.sum(axis=1), ok.sum(axis=1), lo, hi


def reference_runs(row: np.ndarray) -> list:
    """The runs of one row of classes, pixel by pixel: an active pixel fewer than ``MIN_GAP``
    columns after the previous active one extends the current run; otherwise it starts a new
    run, or extends the last one when there are ``MAX_RUNS`` already."""
    runs, last = [], None
    for x, s in enumerate(row):
        if s != ACTIVE:
            continue
        if runs and (x - last <= MIN_GAP or len(runs) == MAX_RUNS):
            runs[-1][1] = x + 1
        else:
            runs.append([x, x + 1])
        last = x
    return runs


def reference_planes(ch, state, inv_scale, origin, inv_pos, halo, stride):
    """Colour planes and guide planes of :class:`layout.Buffers` after :func:`layout.pack`."""
    h, w = state.shape
    surface = (state != BACKGROUND)[..., None]
    with np.errstate(invalid="ignore", over="ignore"):
        v = ch["color"].astype(np.float64) * inv_scale
        color = np.where(np.isnan(v), 0.0, np.clip(v, -layout.COLOR_MAX, layout.COLOR_MAX)).astype(F32)
        normal = np.where(surface, np.clip(ch["normal"].astype(np.float64), -layout.GUIDE_MAX, layout.GUIDE_MAX)
                          .astype(F32), F32(layout.BACKGROUND_NORMAL))
        x = (ch["position"].astype(np.float64) - origin) * inv_pos
        position = np.where(surface, np.clip(x, -layout.GUIDE_MAX, layout.GUIDE_MAX).astype(F32), F32(0.0))
    size = (h + 2 * halo) * stride

    def planes(values, count, fill):
        out = np.full((count, h + 2 * halo, stride), F32(fill))
        out[:, halo:halo + h, halo:halo + w] = np.moveaxis(values, 2, 0)
        return out.reshape(count * size)

    guide = np.concatenate([planes(normal, 3, layout.BACKGROUND_NORMAL), planes(position, 3, 0.0),
                            planes(surface.astype(F32), 1, 0.0)])
    return planes(color, 3, 0.0), guide


# ---------------------------------------------------------------- inputs


def hard_frame(h: int, w: int, seed: int, extra=()) -> dict:
    """Random surfaces with bad values sprinkled over every channel, a sky row, and rows whose
    background pixels make runs with gaps of 1..40 columns (many rows have more than
    ``MAX_RUNS`` runs)."""
    rng = np.random.default_rng(seed)
    color = rng.exponential(1.0, (h, w, 3))
    normal = rng.normal(size=(h, w, 3))
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    position = rng.uniform(-3.0, 5.0, (h, w, 3))
    bad = np.array([np.nan, np.inf, -np.inf, 3e38, -3e38, -0.0, 0.0, 1e-40, -1e-40, 1e12, 1.0000001e12, -5.0])
    for a, frac in ((color, 0.05), (normal, 0.02), (position, 0.02)):
        hit = rng.random(a.shape) < frac
        a[hit] = rng.choice(bad, hit.sum())
    normal[rng.random((h, w)) < 0.03] = 0.0  # zero normals: background
    normal[rng.random((h, w)) < 0.01] = (1e30, -1e30, 0.5)  # finite beyond GUIDE_MAX: a surface
    color[rng.random((h, w)) < 0.01] = 0.0  # zero luminance
    color[rng.random((h, w)) < 0.01] = (1.0, -2.0, 1.0)  # negative luminance
    position[rng.random((h, w)) < 0.01] = -0.0
    # background gaps of 1..40 columns between active stretches of 1..30 columns
    for y in range(2, h, 2):
        x = int(rng.integers(0, 5))
        while x < w:
            x += int(rng.integers(1, 31))
            gap = int(rng.choice([1, MIN_GAP - 2, MIN_GAP - 1, MIN_GAP, MIN_GAP + 1, 40]))
            normal[y, x:x + gap] = 0.0
            x += gap
    normal[0] = 0.0  # a sky row
    ch = {"color": color.astype(F32), "normal": normal.astype(F32), "position": position.astype(F32)}
    if "object_id" in extra:
        ch["object_id"] = np.where(rng.random((h, w)) < 0.05, -1, 3).astype(np.int32)
    if "depth" in extra:
        depth = rng.uniform(1.0, 9.0, (h, w))
        depth[rng.random((h, w)) < 0.05] = rng.choice([np.nan, np.inf, -np.inf], 1)[0]
        ch["depth"] = depth.astype(F32)
    if "variance" in extra:
        var = rng.uniform(0.0, 1.0, (h, w, 3))
        var[rng.random((h, w)) < 0.2] = 0.0
        var[rng.random((h, w, 3)) < 0.1] = 0.0  # zero in one channel only: still noisy
        ch["variance"] = var.astype(F32)
    return ch


def run_survey(ch: dict, b: layout.Buffers) -> None:
    color, normal, position = (np.ascontiguousarray(ch[k]) for k in ("color", "normal", "position"))
    layout.survey(color, normal, position, ch.get("object_id", layout._NO_IDS), ch.get("depth", layout._NO_DEPTH),
                  ch.get("variance", layout._NO_VARIANCE), "object_id" in ch, "depth" in ch, "variance" in ch,
                  b.state, b.row_log, b.row_count, b.row_lo, b.row_hi)


def run_pack(ch: dict, b: layout.Buffers, state, inv_scale, origin, inv_pos) -> None:
    b.state[:] = state
    layout.pack(ch["color"], ch["normal"], ch["position"], b.state, inv_scale, origin, inv_pos, b.halo, b.stride,
                b.color[0], b.color[1], b.guide, b.runs, b.run_count, b.row_surface)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return np.array_equal(a.view(np.uint32), b.view(np.uint32))


SHAPES = [(1, 1), (3, 5), (9, 40), (24, 67), (31, 300), (64, 1283)]
EXTRAS = [(), ("variance",), ("object_id", "depth", "variance")]


# ---------------------------------------------------------------- tests


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("extra", EXTRAS)
def test_survey_matches_reference(shape, extra):
    ch = hard_frame(*shape, seed=shape[0] * 7 + len(extra), extra=extra)
    b = layout.Buffers(*shape, 4)
    run_survey(ch, b)
    state = reference_classes(ch)
    np.testing.assert_array_equal(b.state, state)
    log_sum, count, lo, hi = reference_rows(ch, state)
    np.testing.assert_array_equal(b.row_count, count)
    # fast_log is within 1e-10 of log; the luminance may round differently by an ulp (FMA)
    assert np.all(np.abs(b.row_log - log_sum) <= 1e-6 * np.maximum(count, 1))
    assert np.all(b.row_lo == lo) and np.all(b.row_hi == hi)  # == : -0.0 and 0.0 are one minimum


@pytest.mark.parametrize("shape", SHAPES)
def test_frame_scales_match_reference(shape):
    ch = hard_frame(*shape, seed=shape[1])
    b = layout.Buffers(*shape, 4)
    run_survey(ch, b)
    state = reference_classes(ch)
    log_sum, count, lo, hi = reference_rows(ch, state)
    scale, origin, pos_unit = layout.frame_scales(b.row_log, b.row_count, b.row_lo, b.row_hi, "logmean", "scene")
    want = math.exp(log_sum.sum() / count.sum()) if count.sum() else 1.0
    assert scale == pytest.approx(want, rel=1e-6)  # the luminance may differ by an ulp (FMA)
    surface = state != BACKGROUND
    if surface.any():
        box_lo, box_hi = lo.min(axis=0), hi.max(axis=0)
        assert np.all(origin == box_lo)
        assert pos_unit == pytest.approx(np.linalg.norm(box_hi - box_lo), rel=1e-12)
    else:
        assert np.all(origin == 0.0) and pos_unit == 1.0


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("scales", [(1.0, (0.0, 0.0, 0.0), 1.0), (0.37, (-1.5, 2.0, 0.25), 0.125),
                                    (1e30, (1e30, -3.0, 0.0), 1e-20), (1e-30, (0.0, 0.0, 0.0), 1e20)])
def test_pack_matches_reference_bit_for_bit(shape, scales):
    """Every float of the colour and guide buffers (halo included) and every run, with classes
    from the survey and with random classes (still pixels too)."""
    h, w = shape
    inv_scale, origin, inv_pos = scales[0], np.array(scales[1]), scales[2]
    b = layout.Buffers(h, w, 4)
    for k, seed in enumerate((1, 2)):  # twice on the same buffers: every value is rewritten
        ch = hard_frame(h, w, seed=seed + w)
        state = reference_classes(ch)
        if k == 1:
            rng = np.random.default_rng(seed)
            state = np.where(state == BACKGROUND, BACKGROUND, rng.choice([STILL, ACTIVE, ACTIVE], state.shape))
            state = state.astype(np.int8)
        run_pack(ch, b, state, inv_scale, origin, inv_pos)
        color, guide = reference_planes(ch, state, inv_scale, origin, inv_pos, b.halo, b.stride)
        assert same_bits(b.color[0], color) and same_bits(b.color[1], color)
        assert same_bits(b.guide, guide)
        np.testing.assert_array_equal(b.row_surface, np.any(state != BACKGROUND, axis=1).astype(np.uint8))
        for y in range(h):
            got = b.runs[y, :b.run_count[y]].tolist()
            assert got == reference_runs(state[y]), y


def test_runs_of_designed_rows():
    """Gaps of MIN_GAP - 1 columns merge, gaps of MIN_GAP do not; the ninth and later runs join
    the eighth; still and background pixels both break runs; runs touch both row ends."""
    w = 400
    rows = []

    def row(*spans, fill=BACKGROUND):
        r = np.full(w, fill, np.int8)
        for a, e in spans:
            r[a:e] = ACTIVE
        rows.append(r)

    row((0, 10), (10 + MIN_GAP - 1, 50))  # merged: one run (0, 50)
    row((0, 10), (10 + MIN_GAP, 50))  # two runs
    row(*[(30 * k, 30 * k + 5) for k in range(12)])  # 12 runs: the 8th reaches to 335
    row((0, w))
    row()
    row((w - 1, w), fill=STILL)
    row((5, 6), (5 + MIN_GAP, 5 + MIN_GAP + 1), fill=STILL)  # single pixels MIN_GAP - 1 apart: merged
    state = np.array(rows)
    want = [[[0, 50]], [[0, 10], [10 + MIN_GAP, 50]], [[30 * k, 30 * k + 5] for k in range(7)] + [[210, 335]],
            [[0, w]], [], [[w - 1, w]], [[5, 5 + MIN_GAP + 1]]]
    assert [reference_runs(r) for r in state] == want  # the reference itself
    h = state.shape[0]
    ch = hard_frame(h, w, seed=5)
    b = layout.Buffers(h, w, 2)
    run_pack(ch, b, state, 1.0, np.zeros(3), 1.0)
    assert [b.runs[y, :b.run_count[y]].tolist() for y in range(h)] == want
    np.testing.assert_array_equal(b.row_surface, [1, 1, 1, 1, 0, 1, 1])


def test_nonfinite_luminance_is_not_counted():
    """A surface pixel whose luminance is NaN or infinite is left out of the colour scale (before,
    ``fastmath`` folded the finiteness test of the computed luminance away: an infinite colour
    added about 88.7 to the sum of logs, and this frame's scale was 0.98)."""
    h, w = 4, 33
    ch = hard_frame(h, w, seed=0)
    ch["normal"][:] = (0.0, 0.0, 1.0)
    ch["position"][:] = 1.0
    ch["color"][:] = 0.5
    ch["color"][1, 3] = (np.inf, 0.5, 0.5)
    ch["color"][2, 7] = (np.nan, 0.5, 0.5)
    ch["color"][3, 9] = (np.inf, -np.inf, 0.5)
    b = layout.Buffers(h, w, 4)
    run_survey(ch, b)
    np.testing.assert_array_equal(b.row_count, [w, w - 1, w - 1, w - 1])
    scale = layout.frame_scales(b.row_log, b.row_count, b.row_lo, b.row_hi, "logmean", "scene")[0]
    assert scale == pytest.approx(0.5, rel=1e-9)


@pytest.mark.parametrize("shape", SHAPES)
def test_unpack_matches_reference(shape):
    """The CUDA backend's last step: the change of each active pixel, in units of the colour
    scale, added to its input colour in float64; every other pixel is its input colour."""
    h, w = shape
    ch = hard_frame(h, w, seed=11)
    rng = np.random.default_rng(3)
    state = np.where(reference_classes(ch) == BACKGROUND, BACKGROUND, rng.choice([STILL, ACTIVE], (h, w)))
    state = state.astype(np.int8)
    b = layout.Buffers(h, w, 4)
    filtered = rng.normal(size=b.color[0].shape).astype(F32)
    inv_scale, scale = 1.0 / 0.37, 0.37
    out = np.empty_like(ch["color"])
    layout.unpack(ch["color"], state, filtered, inv_scale, scale, b.halo, b.stride, out)
    planes, _ = reference_planes(ch, state, inv_scale, np.zeros(3), 1.0, b.halo, b.stride)
    size = (h + 2 * b.halo) * b.stride

    def interior(flat):
        return np.moveaxis(flat.reshape(3, h + 2 * b.halo, b.stride)[:, b.halo:b.halo + h, b.halo:b.halo + w], 0, 2)

    assert filtered.size == 3 * size
    color = ch["color"].astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        changed = (color + (interior(filtered).astype(np.float64) - interior(planes)) * scale).astype(F32)
    want = np.where((state == ACTIVE)[..., None], changed, ch["color"])
    finite = np.isfinite(want)
    assert np.array_equal(np.isfinite(out), finite) and np.array_equal(np.isnan(out), np.isnan(want))
    assert same_bits(out[finite], want[finite])
