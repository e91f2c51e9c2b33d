"""Mitsuba's sun and sky: the harness's Hosek-Wilkie model against Mitsuba 3's own ``sunsky`` emitter.

The harness evaluates the model from the coefficients in the installed Mitsuba 3 package
(``plugins/scenes/mitsuba/hosek_wilkie.py``); Mitsuba 3 (``scalar_rgb``) evaluates its ``sunsky``
emitter (``Emitter.eval``) towards the same directions. Sky radiance must agree within
``SKY_RTOL`` relative (Mitsuba computes in float32: the exponentials and the 1.5 power of the
circumsolar term lose a few 1e-6 relative; the bound leaves a factor of ten), solar radiance
within ``SUN_RTOL``: Mitsuba computes the real sun's ``1 - cos(0.2679 degrees)`` in float32, 0.22%
off, which scales its default sun of the real aperture, and its ``complex_sun`` of any other
aperture, by 1.0022 (the harness keeps the exact value); otherwise they agree to 1e-4. Leaving out the
Bezier interpolation over the sun's elevation or the interpolation between the two ground albedos
moves the sky by 5-60%, a thousand times the tolerance (``test_the_comparison_detects_...``).

Needs the optional ``validate`` extra (``pip install -e ".[validate]"``: Mitsuba 3) except for the
fallback test; skipped with a message without it.
"""

from __future__ import annotations

import math
import sys
import textwrap
import warnings

import numpy as np
import pytest

from plugins.scenes.mitsuba import MitsubaWarning, load
from plugins.scenes.mitsuba import hosek_wilkie as hw
from plugins.scenes.mitsuba.sun_sky import SKY_MAP_HEIGHT

SKY_RTOL = 1e-4
SUN_RTOL = 2.5e-3
# (turbidity, sun elevation in degrees, ground albedo, to_world): off the datasets' turbidity levels
# and Bezier control points, per-channel albedo, the classroom's y-up frame and Mitsuba 3's z-up
CASES = [
    (3.0, 24.6, (0.3, 0.3, 0.3), hw.Y_UP),
    (1.7, 61.0, (0.1, 0.5, 0.9), np.eye(3)),
    (7.5, 7.0, (0.8, 0.6, 0.2), hw.Y_UP),
]


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba", reason="Mitsuba 3 is not installed (pip install -e '.[validate]')")
    hw.load_tables.cache_clear()
    tables, reason = hw.load_tables()
    if tables is None:
        pytest.skip(reason)
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def case_params(turbidity, elevation, albedo, to_world, **kw) -> hw.SunskyParams:
    """Parameters with the sun at ``elevation`` degrees in the emitter's frame, azimuth 40 degrees."""
    e, a = math.radians(elevation), math.radians(40.0)
    local = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    return hw.SunskyParams(sun_direction=tuple(np.asarray(to_world, float) @ local), turbidity=turbidity,
                           albedo=albedo, to_world=to_world, **kw)


def mitsuba_emitter(mi, p: hw.SunskyParams):
    """Mitsuba 3's ``sunsky`` with the parameters ``p``."""
    matrix = np.eye(4)
    matrix[:3, :3] = p.to_world
    return mi.load_dict({"type": "sunsky", "sun_direction": mi.ScalarVector3f(*p.sun_direction),
                         "turbidity": p.turbidity, "albedo": {"type": "rgb", "value": list(p.albedo)},
                         "sky_scale": p.sky_scale, "sun_scale": p.sun_scale, "sun_aperture": p.sun_aperture,
                         "complex_sun": p.complex_sun, "to_world": mi.ScalarTransform4f(matrix.tolist())})


def mitsuba_radiance(mi, emitter, directions: np.ndarray) -> np.ndarray:
    """``emitter.eval`` for light arriving from each world direction (N, 3)."""
    out = np.empty((len(directions), 3))
    for k, d in enumerate(directions):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        out[k] = np.array(emitter.eval(si), float)[:3]
    return out


def sphere_directions(n: int, seed: int) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def sky_directions(p: hw.SunskyParams, seed: int) -> np.ndarray:
    """Uniform directions on the sphere plus directions within 20 degrees of the sun."""
    near = hw.cone_directions(np.asarray(p.sun_direction), math.radians(20.0), rings=12, sectors=8)
    return np.concatenate([sphere_directions(300, seed), near])


def sky_error(mi, p: hw.SunskyParams, seed: int = 0) -> float:
    """Largest relative difference of the harness's sky from Mitsuba 3's (relative to the sky's maximum)."""
    d = sky_directions(p, seed)
    theirs = mitsuba_radiance(mi, mitsuba_emitter(mi, p), d)
    ours = hw.radiance(p, hw.load_tables()[0], d)
    return float(np.max(np.abs(ours - theirs) / np.maximum(np.abs(theirs), 1e-3 * np.abs(theirs).max())))


@pytest.mark.parametrize("case", range(len(CASES)))
def test_sky_radiance_matches_mitsuba3(mi, case):
    p = case_params(*CASES[case], sky_scale=2.5, sun_scale=0.0)
    d = sky_directions(p, case)
    theirs = mitsuba_radiance(mi, mitsuba_emitter(mi, p), d)
    ours = hw.radiance(p, hw.load_tables()[0], d)
    below = p.to_local(d)[:, 2] < 0.0
    assert below.any() and np.all(ours[below] == 0.0) and np.all(theirs[below] == 0.0)
    assert np.all(theirs[~below] > 0.0)
    np.testing.assert_allclose(ours, theirs, rtol=SKY_RTOL, atol=0.0)


@pytest.mark.parametrize("complex_sun", [False, True])
@pytest.mark.parametrize("aperture", [hw.SUN_APERTURE, 10.08])
@pytest.mark.parametrize("case", [0, 2])
def test_sun_radiance_matches_mitsuba3(mi, case, aperture, complex_sun):
    """Solar radiance inside the disc: Mitsuba 3's default uniform sun (tabulated irradiance spectrum in
    RGB) and its ``complex_sun`` (limb darkening, elevation segments); the aperture's area ratio."""
    p = case_params(*CASES[case], sky_scale=0.0, sun_scale=3.0, sun_aperture=aperture, complex_sun=complex_sun)
    d = hw.cone_directions(np.asarray(p.sun_direction), 0.999 * p.half_aperture, rings=16, sectors=12)
    theirs = mitsuba_radiance(mi, mitsuba_emitter(mi, p), d)
    ours = hw.radiance(p, hw.load_tables()[0], d)
    assert np.all(theirs[:, 0] > 0.0)  # (blue can be slightly negative at the limb: Mitsuba's RGB fit)
    np.testing.assert_allclose(ours, theirs, rtol=SUN_RTOL, atol=1e-4 * np.abs(theirs).max())
    outside = hw.cone_directions(np.asarray(p.sun_direction), 3.0 * p.half_aperture, rings=4, sectors=4)[-4:]
    assert np.all(hw.radiance(p, hw.load_tables()[0], outside) == 0.0)
    if complex_sun:  # the limb is darker than the centre, redder at low elevation
        centre, limb = ours[0], ours[-1]
        assert np.all(limb < centre)


def test_the_comparison_detects_a_missing_interpolation(mi, monkeypatch):
    """Without the Bezier curve (nearest control point) or the albedo interpolation (albedo 0 taken), the
    sky error is far above the tolerance; with them it is within it."""
    p = case_params(*CASES[1], sky_scale=1.0, sun_scale=0.0)
    assert sky_error(mi, p) <= SKY_RTOL
    weights = hw.bezier_weights

    def nearest_control_point(elevation):
        w = weights(elevation)
        return (w == w.max()).astype(float)

    monkeypatch.setattr(hw, "bezier_weights", nearest_control_point)
    assert sky_error(mi, p) > 0.05
    monkeypatch.setattr(hw, "bezier_weights", weights)
    assert sky_error(mi, p) <= SKY_RTOL
    dropped = hw.SunskyParams(**{**p.__dict__, "albedo": (0.0, 0.0, 0.0)})
    d = sky_directions(p, 0)
    theirs = mitsuba_radiance(mi, mitsuba_emitter(mi, p), d)
    ours = hw.radiance(dropped, hw.load_tables()[0], d)
    assert float(np.max(np.abs(ours - theirs) / np.maximum(theirs, 1e-12))) > 0.05


CLASSROOM_LIKE = """\
<scene version="0.6.0">
  <sensor type="perspective"><float name="fov" value="60"/>
    <transform name="toWorld"><lookat origin="0, 1, 4" target="0, 1, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
  </sensor>
  <shape type="rectangle"><transform name="toWorld"><rotate x="1" angle="-90"/><scale value="3"/></transform>
    <bsdf type="diffuse"/></shape>
  <emitter type="sunsky">
    <float name="turbidity" value="3"/>
    <vector name="sunDirection" x="-0.865804" y="0.416766" z="-0.276929"/>
    <float name="skyScale" value="6"/>
    <float name="sunScale" value="10"/>
    <float name="sunRadiusScale" value="18.8131"/>
  </emitter>
</scene>
"""


def load_quietly(folder):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        return load(folder)


def test_a_mitsuba_06_sunsky_renders_as_mitsuba3_reads_it(mi, tmp_path):
    """The classroom's emitter: parameters mapped (y up, sunRadiusScale as aperture), the baked map as the
    path tracer reads it equal to Mitsuba 3's sky at texel centres, the disc's radiance the mean of its sun."""
    from plugins.renderers.pathtracer import lights as L

    (tmp_path / "scene.xml").write_text(CLASSROOM_LIKE)
    scene = load_quietly(tmp_path)
    record = scene.params["sunsky"]
    assert record["model"] == "hosek-wilkie"
    assert record["sky_scale"] == 6.0 and record["sun_scale"] == 10.0 and record["turbidity"] == 3.0
    assert record["sun_aperture"] == pytest.approx(hw.SUN_APERTURE * 18.8131)
    assert record["albedo"] == [0.3, 0.3, 0.3]
    assert np.allclose(record["to_world"], hw.Y_UP)
    assert any("Hosek-Wilkie model evaluated" in m for m in scene.params["approximations"])
    p = hw.SunskyParams(**{k: v for k, v in record.items() if k != "model"})
    env = scene.environment
    height = SKY_MAP_HEIGHT
    assert env.kind == "map" and env.image.shape == (height, 2 * height, 3)
    lp = np.zeros(L.N_PARAMS)
    lp[L.ENV_KIND] = L.ENV_MAP
    lp[L.ENV_RAD:L.ENV_RAD + 3] = env.radiance
    lp[L.SUN_COS] = 1.0
    rng = np.random.default_rng(3)
    rows, cols = rng.integers(0, height, 200), rng.integers(0, 2 * height, 200)
    d = hw.map_directions(height)[rows, cols]
    ours = np.array([L.infinite_radiance.py_func(v, lp, env.image) for v in d])
    sky_only = mitsuba_emitter(mi, hw.SunskyParams(**{**p.__dict__, "sun_scale": 0.0}))
    theirs = mitsuba_radiance(mi, sky_only, d)
    assert np.all(ours[d[:, 1] < 0] == 0.0) and np.all(ours[d[:, 1] > 0] > 0.0)
    np.testing.assert_allclose(ours, theirs, rtol=SKY_RTOL, atol=0.0)
    sun = scene.sun
    assert sun.angular_radius == pytest.approx(0.5 * record["sun_aperture"])
    assert np.allclose(sun.direction, p.sun_direction)
    inside = hw.cone_directions(np.asarray(p.sun_direction), 0.999 * p.half_aperture, rings=64, sectors=32)
    sun_only = mitsuba_emitter(mi, hw.SunskyParams(**{**p.__dict__, "sky_scale": 0.0}))
    np.testing.assert_allclose(sun.radiance, mitsuba_radiance(mi, sun_only, inside).mean(axis=0), rtol=SUN_RTOL)


def test_without_mitsuba_the_gradient_stays_and_the_warning_says_why(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba", None)
    hw.load_tables.cache_clear()
    try:
        (tmp_path / "scene.xml").write_text(CLASSROOM_LIKE)
        with pytest.warns(MitsubaWarning) as caught:
            scene = load(tmp_path)
    finally:
        hw.load_tables.cache_clear()
    assert scene.params["sunsky"]["model"] == "gradient"
    assert scene.environment.kind == "sky" and scene.sun is not None
    assert scene.sun.angular_radius == pytest.approx(0.5 * hw.SUN_APERTURE * 18.8131)
    (note,) = [m for m in scene.params["approximations"] if "Hosek-Wilkie" in m]
    assert "Mitsuba 3 is not installed" in note and 'pip install -e ".[validate]"' in note
    assert note in [str(w.message) for w in caught]


def test_sky_and_sun_kinds_and_mitsuba3_frames(mi, tmp_path):
    """Mitsuba 0.6's ``sky`` (no sun) and a Mitsuba 3 ``sunsky`` with ``to_world`` (z up by default)."""
    (tmp_path / "scene.xml").write_text(textwrap.dedent("""\
        <scene version="0.6.0">
          <emitter type="sky"><vector name="sunDirection" x="0" y="1" z="1"/><float name="scale" value="2"/>
            <spectrum name="albedo" value="0.5"/></emitter>
          <shape type="sphere"><bsdf type="diffuse"/></shape>
        </scene>"""))
    scene = load_quietly(tmp_path)
    assert scene.sun is None and scene.environment.kind == "map"
    assert scene.params["sunsky"]["sky_scale"] == 2.0 and scene.params["sunsky"]["sun_scale"] == 0.0
    assert scene.params["sunsky"]["albedo"] == [0.5, 0.5, 0.5]
    (tmp_path / "scene.xml").write_text(textwrap.dedent("""\
        <scene version="3.0.0">
          <emitter type="sunsky"><vector name="sun_direction" x="0" y="0.5" z="1"/>
            <float name="sun_aperture" value="2"/></emitter>
          <shape type="sphere"><bsdf type="diffuse"/></shape>
        </scene>"""))
    scene = load_quietly(tmp_path)
    image = scene.environment.image
    assert np.allclose(scene.params["sunsky"]["to_world"], np.eye(3))
    assert scene.sun.angular_radius == pytest.approx(1.0)
    # z up: the map's +z and -z texels (the row above the horizon, u = 0 and 0.5) are lit and black
    row = SKY_MAP_HEIGHT // 2 - 1
    assert image[row, 0].min() > 0.0 and image[row, SKY_MAP_HEIGHT].max() == 0.0
