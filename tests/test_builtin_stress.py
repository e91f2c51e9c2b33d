"""Numerical stress cases (issue 18) for the built-in filters ``eaw``, ``svgf``, ``opencv_jbf``, ``oidn``.

Each case perturbs a plausible frame (``harness.testing.frames.make_frame``, holding exactly
the channels the filter declares) the way a user's data might: extreme colour values, NaN /
infinite / huge values in every guide channel, degenerate geometry, odd shapes, long and cut
sequences. The properties are bounds, not golden numbers:

* every output value is finite (every case keeps the colour finite);
* convex filters (``eaw``, ``opencv_jbf``) stay within the input colour's range per channel;
* a pixel whose geometry is unusable (NaN normal) is passed through by ``eaw`` and ``svgf``;
* a constant image stays constant where the filter promises it.

The case table :data:`COLOR_CASES` / :func:`guide_cases` is plain data so that a stress command
can run the same cases.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from harness import load_plugins
from harness.testing.frames import make_frame

ROOT = Path(__file__).resolve().parents[1]
FILTERS = ("eaw", "svgf", "opencv_jbf", "oidn")
#: filters whose every output pixel is a convex combination of input colours
CONVEX = {"eaw", "opencv_jbf"}
#: filters that pass a pixel with an unusable normal through unchanged
PASS_THROUGH_BAD_GEOMETRY = {"eaw", "svgf"}
F32_MAX = np.float32(np.finfo(np.float32).max)
H, W = 20, 24


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def _spec(registry, name):
    if name not in registry.filters:
        pytest.skip(f"filter {name!r} is not registered (optional extra missing)")
    return registry.filters[name]


def _frames(spec, h=H, w=W, n=None):
    n = (3 if spec.temporal else 1) if n is None else n
    return [make_frame(h, w, spec.requires | spec.optional, seed=t, index=t) for t in range(n)]


def _run(spec, frames):
    f = spec.factory(backend="cpu")
    return f, [np.array(f(fr), copy=True) for fr in frames]


def _with_color(frame, color):
    """``frame`` with a new colour; ``direct``/``indirect`` (where present) split it 60/40."""
    color = np.asarray(color, np.float32)
    arrays = {"color": color}
    if "direct" in frame:
        arrays["direct"] = (color * np.float32(0.6)).astype(np.float32)
        arrays["indirect"] = (color - arrays["direct"]).astype(np.float32)
    if "emission" in frame:
        arrays["emission"] = np.zeros_like(color)
    return frame.replace(**arrays)


# ---------------------------------------------------------------- colour cases


def _fireflies(value):
    def make(c, rng):
        idx = rng.integers(0, c.shape[0] * c.shape[1], size=max(1, c.shape[0] * c.shape[1] // 40))
        c.reshape(-1, 3)[idx] = value
        return c

    return make


def _f32max_negzero(c, rng):
    c[::5, ::3] = F32_MAX
    c[1::4, ::2] = -0.0
    return c


def _one_3e38(c, rng):
    c[3, 4] = 3e38
    return c


def _dynamic_range(c, rng):
    c[:] = 1e-30
    c[::2, ::2] = 1e30
    return c


COLOR_CASES = {
    "firefly_1e3": _fireflies(1e3),
    "firefly_1e5": _fireflies(1e5),
    "firefly_1e8": _fireflies(1e8),
    "f32max_and_negzero": _f32max_negzero,
    "dynamic_range_1e-30_1e30": _dynamic_range,
    "denormals": lambda c, rng: (c * np.float32(1e-40)).astype(np.float32),
    "all_zero": lambda c, rng: np.zeros_like(c),
    "all_constant": lambda c, rng: np.full_like(c, 0.37),
    "negative": lambda c, rng: c - np.float32(0.5) * c.mean(),
    "one_3e38": _one_3e38,
}


@pytest.mark.parametrize("case", sorted(COLOR_CASES))
@pytest.mark.parametrize("name", FILTERS)
def test_color_cases_finite_and_bounded(registry, name, case):
    spec = _spec(registry, name)
    frames = []
    for t, fr in enumerate(_frames(spec)):
        color = COLOR_CASES[case](fr["color"].copy(), np.random.default_rng(t))
        frames.append(_with_color(fr, color))
    _, outs = _run(spec, frames)
    for fr, out in zip(frames, outs):
        assert out.shape == fr["color"].shape and out.dtype == np.float32
        assert np.isfinite(out).all(), f"{name}: non-finite output on colour case {case}"
        if name in CONVEX:
            c = fr["color"].astype(np.float64)
            lo, hi = c.min(axis=(0, 1)), c.max(axis=(0, 1))
            tol = 1e-6 * np.maximum(np.abs(lo), np.abs(hi)) + 1e-5 * (hi - lo) + 1e-37  # float rounding
            assert np.all(out >= lo - tol) and np.all(out <= hi + tol), f"{name}: out of range on {case}"
        if case == "all_constant" and name != "oidn":
            np.testing.assert_allclose(out, 0.37, rtol=1e-5)


def test_colour_only_perturbation_reaches_svgf(registry):
    """With ``direct``/``indirect`` present, SVGF still follows ``color`` (the authority): a
    firefly added to ``color`` alone shows in the output, and NaN in ``indirect`` is ignored."""
    spec = _spec(registry, "svgf")
    frame = _frames(spec, n=1)[0]
    base = spec.factory(backend="cpu")(frame)
    color = frame["color"].copy()
    color[5, 6] += 50.0
    bumped = spec.factory(backend="cpu")(frame.replace(color=color))
    assert bumped[5, 6].sum() > base[5, 6].sum() + 1.0
    indirect = frame["indirect"].copy()
    indirect[5, 6] = np.nan
    out = spec.factory(backend="cpu")(frame.replace(indirect=indirect))
    assert np.isfinite(out).all()


def test_negative_colour_behaviour(registry):
    """Negative radiance: ``eaw``, ``svgf`` and ``opencv_jbf`` filter signed values (a negative
    constant stays that constant); ``oidn`` clamps to 0 and counts the repaired values."""
    for name in FILTERS:
        spec = _spec(registry, name)
        frame = _with_color(_frames(spec, n=1)[0], np.full((H, W, 3), -0.25, np.float32))
        f = spec.factory(backend="cpu")
        out = f(frame)
        if name == "oidn":
            assert f.repaired == H * W * 3 and np.all(np.abs(out) < 0.05)
        else:
            np.testing.assert_allclose(out, -0.25, rtol=1e-5)


@pytest.mark.parametrize("level", [1e30, 1e-30, 3e38, 1.0])
def test_oidn_keeps_the_level_of_extreme_constants(registry, level):
    """A constant image comes back near its own level (it was clamped to 6e4, and a dim image
    came back at OIDN's floor of about 1e-3)."""
    spec = _spec(registry, "oidn")
    frame = _with_color(_frames(spec, n=1)[0], np.full((H, W, 3), level, np.float32))
    out = spec.factory(backend="cpu")(frame).astype(np.float64)
    assert np.isfinite(out).all()
    assert abs(out.mean() / level - 1.0) < 0.05, out.mean()


# ---------------------------------------------------------------- guide cases

GUIDE_VALUES = {"nan": np.nan, "posinf": np.inf, "neginf": -np.inf, "f32max": F32_MAX, "neg_f32max": -F32_MAX}


def guide_cases(channels):
    """(case name, function frame -> frame) for every guide channel in ``channels``."""
    cases = []
    for ch in sorted(channels - {"color", "object_id"}):
        for label, value in GUIDE_VALUES.items():
            for where in ("one", "all"):
                def make(fr, ch=ch, value=value, where=where):
                    a = fr[ch].copy()
                    if where == "one":
                        a[3, 4] = value
                    else:
                        a[:] = value
                    return fr.replace(**{ch: a})

                cases.append((f"{ch}_{label}_{where}", make))
    return cases


def _zero_normal(fr, where):
    n = fr["normal"].copy()
    n[3:6, 4:7] = 0.0
    if where == "all":
        n[:] = 0.0
    return fr.replace(normal=n)


SPECIAL_CASES = {
    "normal_zero_length_some": lambda fr: _zero_normal(fr, "some"),
    "normal_zero_length_all": lambda fr: _zero_normal(fr, "all"),
    "depth_zero": lambda fr: fr.replace(depth=np.zeros_like(fr["depth"])) if "depth" in fr else fr,
    "depth_inf": lambda fr: fr.replace(depth=np.full_like(fr["depth"], np.inf)) if "depth" in fr else fr,
    "albedo_zero": lambda fr: fr.replace(albedo=np.zeros_like(fr["albedo"])) if "albedo" in fr else fr,
    "motion_far_outside": (lambda fr: fr.replace(motion=np.full_like(fr["motion"], 1e6)) if "motion" in fr else fr),
    "motion_far_outside_negative": (
        lambda fr: fr.replace(motion=np.full_like(fr["motion"], -3e38)) if "motion" in fr else fr),
    "object_id_minus_one": (
        lambda fr: fr.replace(object_id=np.full_like(fr["object_id"], -1)) if "object_id" in fr else fr),
    "object_id_huge": (
        lambda fr: fr.replace(object_id=np.full_like(fr["object_id"], 2**31 - 1)) if "object_id" in fr else fr),
}


def _guide_params():
    reg = load_plugins()
    params = []
    for name in FILTERS:
        if name not in reg.filters:
            continue
        spec = reg.filters[name]
        for case, _ in guide_cases(spec.requires | spec.optional):
            params.append((name, case))
        params.extend((name, case) for case in SPECIAL_CASES)
    return params


def _case_function(spec, case):
    table = dict(guide_cases(spec.requires | spec.optional))
    return table[case] if case in table else SPECIAL_CASES[case]


@pytest.mark.parametrize("name,case", _guide_params())
def test_guide_cases_finite(registry, name, case):
    spec = _spec(registry, name)
    if name == "opencv_jbf":
        pytest.skip("run in a subprocess by test_opencv_jbf_guides_in_subprocess (it used to crash)")
    make = _case_function(spec, case)
    frames = [make(fr) for fr in _frames(spec)]
    _, outs = _run(spec, frames)
    for fr, out in zip(frames, outs):
        assert np.isfinite(out).all(), f"{name}: non-finite output on guide case {case}"
        if name in CONVEX:
            c = fr["color"]
            assert out.min() >= c.min() - 1e-5 and out.max() <= c.max() + 1e-5
        if case == "normal_nan_one" and name in PASS_THROUGH_BAD_GEOMETRY:
            np.testing.assert_array_equal(out[3, 4], fr["color"][3, 4])


def test_opencv_jbf_guides_in_subprocess():
    """Every guide case of ``opencv_jbf`` in a child process: a NaN, infinite or 3.4e38 normal
    used to crash the process (segmentation fault) or give non-finite output."""
    reg = load_plugins()
    if "opencv_jbf" not in reg.filters:
        pytest.skip("opencv_jbf is not registered (the peers extra is missing)")
    script = textwrap.dedent(
        """
        import numpy as np
        import tests.test_builtin_stress as t
        from harness import load_plugins
        spec = load_plugins().filters["opencv_jbf"]
        for name, case in t._guide_params():
            if name != "opencv_jbf":
                continue
            frame = t._case_function(spec, case)(t._frames(spec)[0])
            out = spec.factory(backend="cpu")(frame)
            assert np.isfinite(out).all(), case
            c = frame["color"]
            assert out.min() >= c.min() - 1e-6 and out.max() <= c.max() + 1e-6, case
        print("ALL-OK")
        """
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0 and "ALL-OK" in proc.stdout, (
        f"exit status {proc.returncode} (-11 is a segmentation fault)\n{proc.stderr[-2000:]}")


# ---------------------------------------------------------------- shapes


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (7, 5), (33, 17), (2, 3)])
@pytest.mark.parametrize("name", FILTERS)
def test_shapes(registry, name, shape):
    spec = _spec(registry, name)
    frames = _frames(spec, *shape)
    _, outs = _run(spec, frames)
    for out in outs:
        assert out.shape == (*shape, 3) and np.isfinite(out).all()


# ---------------------------------------------------------------- sequences (temporal filters)


def _noisy_static(t, h=10, w=12):
    """Frame ``t`` of a static scene: the same geometry, fresh exponential noise on the colour."""
    fr = make_frame(h, w, {"color", "albedo", "normal", "depth", "object_id", "motion", "direct", "indirect",
                           "emission"}, seed=0, index=t)
    rng = np.random.default_rng(1000 + t)
    clean = fr["albedo"] * np.float32(0.8)
    return _with_color(fr, (clean * rng.exponential(1.0, clean.shape[:2] + (1,))).astype(np.float32)), clean


def test_svgf_thousand_static_frames_converge(registry):
    """1,000 frames of a static noisy scene: history capped, output energy bounded, no drift."""
    spec = _spec(registry, "svgf")
    f = spec.factory(backend="cpu")
    means, errors = [], []
    for t in range(1000):
        frame, clean = _noisy_static(t)
        out = f(frame)
        assert np.isfinite(out).all(), t
        means.append(float(out.mean()))
        errors.append(float(np.abs(out - clean).mean()))
    means, errors = np.array(means), np.array(errors)
    assert f.history_length().max() <= spec.params["max_history"]
    truth = float(clean.mean())
    # energy: within 15 % of the clean image after the average has filled, for every frame
    assert np.all(np.abs(means[20:] - truth) < 0.15 * truth), (means[20:].min(), means[20:].max(), truth)
    # converged, not drifting: the error of the last 100 frames equals that of frames 100-200
    assert errors[-100:].mean() < 1.15 * errors[100:200].mean()
    assert errors[-100:].mean() < 0.5 * errors[0]
    assert np.all(f.variance_estimate() >= 0.0)


def test_svgf_camera_cuts_and_alternating_resolutions(registry):
    spec = _spec(registry, "svgf")
    f = spec.factory(backend="cpu")
    sizes = [(10, 12), (7, 9), (10, 12), (1, 1), (16, 5)]
    for t in range(15):
        h, w = sizes[t % len(sizes)]
        frame = make_frame(h, w, spec.requires | spec.optional, seed=t, index=t)
        if t % 3 == 0:
            f.reset()
        out = f(frame.with_meta(camera_cut=t % 4 == 0))
        assert out.shape == (h, w, 3) and np.isfinite(out).all()
        if t % 3 == 0 or t % 4 == 0 or sizes[(t - 1) % len(sizes)] != (h, w):
            # no usable history: the output equals a fresh filter's
            np.testing.assert_array_equal(out, spec.factory(backend="cpu")(frame))



# ---------------------------------------------------------------- the harness's repair policy upstream


def _broken_everywhere(fr):
    """``fr`` with NaN, +-inf and 3e38 at a few pixels of every float channel."""
    arrays = {}
    for ch in fr.channels:
        a = fr[ch].copy()
        if a.dtype.kind != "f":
            continue
        for (y, x), value in zip(((2, 3), (4, 5), (6, 7), (1, 1), (8, 2)), (np.nan, np.inf, -np.inf, 3e38, -3e38)):
            a[y, x] = value
        arrays[ch] = a
    return fr.replace(**arrays)


@pytest.mark.parametrize("name", FILTERS)
def test_repaired_frames_pass(registry, name):
    """Frames repaired by ``--nonfinite repair`` (harness.nonfinite) never crash a filter, and
    its output is finite."""
    from harness.nonfinite import apply_nonfinite_policy

    spec = _spec(registry, name)
    frames = []
    for fr in _frames(spec):
        repaired, count = apply_nonfinite_policy(_broken_everywhere(fr), "repair")
        assert count > 0
        frames.append(repaired)
    _, outs = _run(spec, frames)
    for out in outs:
        assert np.isfinite(out).all(), f"{name}: non-finite output on a repaired frame"
