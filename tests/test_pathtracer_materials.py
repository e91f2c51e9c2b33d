"""Mitsuba material semantics in the path tracer that need no Mitsuba: masks and first hits,
one-sided emitters, Mitsuba's plastic against its closed form, the rough-interface tables."""

from __future__ import annotations

import textwrap
import warnings

import numpy as np
import pytest

from plugins.renderers.pathtracer import PathTracer
from plugins.renderers.pathtracer.materials import fresnel_diffuse_reflectance, rough_interface
from plugins.scenes.mitsuba import MitsubaWarning, load

CAMERA = """<sensor type="perspective"><float name="fov" value="30"/>
  <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>"""


def _scene(tmp_path, body: str):
    (tmp_path / "scene.xml").write_text(textwrap.dedent(f'<scene version="3.0.0">{CAMERA}{body}</scene>'))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        return load(tmp_path)


def _png(path, rgb) -> None:
    import OpenImageIO as oiio

    img = np.ascontiguousarray(np.broadcast_to(np.asarray(rgb, np.uint8), (4, 4, 3)))
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(4, 4, 3, "uint8"))
    out.write_image(img)
    out.close()


def test_mask_of_opacity_zero_is_not_a_first_hit(tmp_path):
    """A plane whose mask opacity is 0 everywhere: first hits (G-buffer) and colour come from the
    wall behind it; at opacity 1 from the plane itself."""
    for value, visible in ((0, "wall"), (255, "plane")):
        _png(tmp_path / "opacity.png", (value, value, value))
        scene = _scene(tmp_path, """
          <shape type="rectangle" id="plane"><bsdf type="mask"><texture type="bitmap" name="opacity">
            <string name="filename" value="opacity.png"/></texture>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.9, 0.1, 0.1"/></bsdf></bsdf></shape>
          <shape type="rectangle" id="wall"><transform name="to_world"><scale value="3"/><translate z="-1"/>
            </transform><bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.1, 0.9"/></bsdf></shape>
          <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>""")
        frame = PathTracer(max_depth=4).render(scene, 0, spp=16, channels={"object_id", "albedo"})
        names = [o.name for o in scene.objects]
        centre = frame["object_id"][8, 8]
        assert names[centre] == visible
        colour = frame["color"][8, 8]
        assert (colour[0] > colour[2]) == (visible == "plane")


def test_area_emitter_is_one_sided(tmp_path):
    """Mitsuba's area light emits on its normal's side only: seen from behind it is black, and it
    lights nothing behind it."""
    for flip, lit in ((False, True), (True, False)):
        rotate = '<rotate y="1" angle="180"/>' if flip else ""
        scene = _scene(tmp_path, f"""
          <shape type="rectangle"><transform name="to_world">{rotate}</transform>
            <emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter></shape>""")
        frame = PathTracer(max_depth=3).render(scene, 0, spp=4, channels={"emission"})
        assert (frame["color"][8, 8] > 1.9).all() == lit
        np.testing.assert_array_equal(frame["emission"][8, 8], frame["color"][8, 8])


def test_smooth_plastic_under_a_constant_sky_matches_its_closed_form(tmp_path):
    """A plane of Mitsuba's ``plastic`` seen head-on under a sky of radiance 1: the reflected radiance is
    ``F(1) + R / (1 - F_dr) / eta^2 (1 - F(1)) * integral of (1 - F(cos)) cos / pi``."""
    scene = _scene(tmp_path, """
      <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform>
        <bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.5, 0.5, 0.5"/>
        <float name="int_ior" value="1.5"/><float name="ext_ior" value="1"/></bsdf></shape>
      <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>""")
    frame = PathTracer(max_depth=2).render(scene, 0, spp=4096, channels={"variance"}, resolution=(4, 4))
    eta = 1.5
    mu = (np.arange(20000) + 0.5) / 20000

    def fresnel(c):
        ct = np.sqrt(1 - (1 - c * c) / eta**2)
        return 0.5 * (((c - eta * ct) / (c + eta * ct)) ** 2 + ((eta * c - ct) / (eta * c + ct)) ** 2)

    f1 = fresnel(1.0)
    hemi = 2.0 * np.mean((1 - fresnel(mu)) * mu)  # (1/pi) integral of (1 - F) cos over the hemisphere
    expected = f1 + 0.5 / (1 - fresnel_diffuse_reflectance(1 / eta)) / eta**2 * (1 - f1) * hemi
    pixel = frame["color"][1:3, 1:3].mean(axis=(0, 1))
    err = np.sqrt(frame["variance"][1:3, 1:3].mean(axis=(0, 1)) / 4)
    assert np.all(np.abs(pixel - expected) < 5 * err + 1e-4), (pixel, expected)
    # without the Fresnel transmittance in and out the same pixels would be this much brighter
    assert abs(0.5 / (1 - fresnel_diffuse_reflectance(1 / eta)) / eta**2 + f1 - expected) > 20 * err.max()


def test_rough_interface_tends_to_the_smooth_fresnel():
    mu = np.linspace(0.2, 1.0, 9)
    reflectance, transmittance = rough_interface(mu, 1e-3, 1.5, beckmann=False)
    ct = np.sqrt(1 - (1 - mu**2) / 1.5**2)
    fresnel = 0.5 * (((mu - 1.5 * ct) / (mu + 1.5 * ct)) ** 2 + ((1.5 * mu - ct) / (1.5 * mu + ct)) ** 2)
    np.testing.assert_allclose(reflectance, fresnel, atol=2e-3)
    np.testing.assert_allclose(transmittance, 1 - fresnel, atol=2e-3)
    rough_r, rough_t = rough_interface(mu, 0.5, 1.5, beckmann=True)
    assert np.all(rough_r + rough_t <= 1.0 + 1e-6) and np.all(rough_r + rough_t > 0.8)


@pytest.mark.parametrize("eta", [1.2, 1.5, 2.0])
def test_diffuse_fresnel_reflectance_fit(eta):
    """Mitsuba's fit against the integral 2 int F(mu, 1/eta) mu dmu from inside the dielectric."""
    mu = (np.arange(200000) + 0.5) / 200000
    inv = 1.0 / eta
    sin_t2 = (1 - mu**2) / inv**2
    ct = np.sqrt(np.maximum(1 - sin_t2, 0))
    f = 0.5 * (((mu - inv * ct) / (mu + inv * ct)) ** 2 + ((inv * mu - ct) / (inv * mu + ct)) ** 2)
    f = np.where(sin_t2 >= 1, 1.0, f)
    assert fresnel_diffuse_reflectance(inv) == pytest.approx(2 * np.mean(f * mu), rel=1e-2)


def _lambert_irradiance(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Irradiance over radiance of a polygon seen from points of a plane of normal +y (Lambert's formula:
    half the sum over edges of the edge's angle times the normal's component along the edge plane's normal)."""
    total = np.zeros(points.shape[:-1])
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        va = (a - points) / np.linalg.norm(a - points, axis=-1, keepdims=True)
        vb = (b - points) / np.linalg.norm(b - points, axis=-1, keepdims=True)
        c = np.cross(va, vb)
        norm = np.linalg.norm(c, axis=-1)
        total += np.arctan2(norm, (va * vb).sum(-1)) * c[..., 1] / norm
    return np.abs(total) / 2.0


def test_area_light_direct_lighting_matches_lambert(tmp_path):
    """Direct light (``max_depth`` 2) of a one-sided square emitter on a diffuse floor against Lambert's
    closed-form irradiance at each pixel's first hit: the image sum within 4 standard errors and 0.4%.
    (Mitsuba 3 ``scalar_rgb`` matches the same closed form to 0.01%: docs/pathtracer.md.)"""
    (tmp_path / "scene.xml").write_text(textwrap.dedent("""\
      <scene version="3.0.0">
      <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 3, 0.01" target="0, 0, 0" up="0, 0, -1"/></transform></sensor>
      <shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
      <shape type="rectangle"><transform name="to_world"><scale value="0.6"/><rotate x="1" angle="90"/>
        <translate x="0.5" y="1.0" z="0.4"/></transform>
        <emitter type="area"><rgb name="radiance" value="10, 10, 10"/></emitter></shape>
      </scene>"""))
    scene = load(tmp_path)
    frame = PathTracer(max_depth=2).render(scene, 0, spp=1024, seed=3, channels={"variance", "position"},
                                           resolution=(32, 32))
    corners = np.array([[-0.6, 0, -0.6], [0.6, 0, -0.6], [0.6, 0, 0.6], [-0.6, 0, 0.6]]) + (0.5, 1.0, 0.4)
    position = frame["position"].astype(np.float64)
    floor = np.isfinite(position).all(axis=-1) & (np.abs(position[..., 1]) < 1e-4)
    expected = 0.5 / np.pi * 10.0 * _lambert_irradiance(position[floor], corners)
    got = frame["color"].astype(np.float64)[floor]
    error = np.sqrt(frame["variance"].astype(np.float64)[floor].sum(axis=0))
    assert floor.sum() > 500
    assert np.all(np.abs(got.sum(axis=0) - expected.sum()) < 4 * error), (got.sum(axis=0) / expected.sum(), error)
    assert np.all(np.abs(got.sum(axis=0) / expected.sum() - 1) < 4e-3)


@pytest.mark.parametrize("from_x", [1.0, -1.0])
def test_bumpmap_tilts_the_shading_normal_by_the_height_gradient(tmp_path, from_x):
    """A diffuse plane under ``bumpmap`` with a height ramp along u, lit by a directional light at 40
    degrees from +x or -x, direct light only: every pixel is ``R / pi E max(<n_b, l>, 0) G`` with the
    bump normal ``n_b = normalize(-g_u, 0, |dp/du|)`` and Mitsuba's shadowing factor ``G``
    (``docs/pathtracer.md``); without the height the plane would be ``R / pi E cos 40``: 49% and 21% off."""
    import OpenImageIO as oiio

    ramp = np.broadcast_to((np.arange(64) * 4).astype(np.uint8)[None, :, None], (8, 64, 3))
    out = oiio.ImageOutput.create(str(tmp_path / "ramp.png"))
    out.open(str(tmp_path / "ramp.png"), oiio.ImageSpec(64, 8, 3, "uint8"))
    out.write_image(np.ascontiguousarray(ramp))
    out.close()
    angle = np.radians(40.0)
    light = np.array([from_x * np.sin(angle), 0.0, np.cos(angle)])
    scene = _scene(tmp_path, f"""
      <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform>
        <bsdf type="bumpmap"><texture type="bitmap"><string name="filename" value="ramp.png"/>
          <boolean name="raw" value="true"/></texture><float name="scale" value="4"/>
          <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></bsdf></shape>
      <emitter type="directional"><vector name="direction" x="{-light[0]}" y="0" z="{-light[2]}"/>
        <rgb name="irradiance" value="3, 3, 3"/></emitter>""")
    frame = PathTracer(max_depth=2).render(scene, 0, spp=16, resolution=(8, 8))
    g_u = 4.0 * 256.0 / 255.0  # scale x d(4 c / 255)/du with c = 64 u - 1/2
    n_b = np.array([-g_u, 0.0, 8.0]) / np.hypot(g_u, 8.0)  # |dp/du| = 2 x 4
    tan2_b = (g_u / 8.0) ** 2
    a2 = min(tan2_b / 8.0, 1.0)
    shadowing = 2.0 / (1.0 + np.sqrt(1.0 + a2 * np.tan(angle) ** 2))
    expected = 0.5 / np.pi * 3.0 * max(float(n_b @ light), 0.0) * shadowing
    np.testing.assert_allclose(frame["color"].astype(np.float64), expected, rtol=5e-3)


def test_spot_light_direct_lighting_matches_its_closed_form(tmp_path):
    """A ``spot`` above a diffuse floor, direct light only: each pixel is ``R / pi I f(theta) cos_s / d^2``
    (``f``: Mitsuba's falloff, 1 within ``beam_width``, linear in the angle to 0 at ``cutoff_angle``);
    the spot is a delta light, so the estimate is exact up to float rounding, inside, across and
    outside the falloff ring."""
    (tmp_path / "scene.xml").write_text(textwrap.dedent("""\
      <scene version="3.0.0">
      <sensor type="perspective"><float name="fov" value="60"/>
        <transform name="to_world"><lookat origin="0, 3, 0.01" target="0, 0, 0" up="0, 0, -1"/></transform></sensor>
      <shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
      <emitter type="spot"><rgb name="intensity" value="4, 3, 2"/><float name="cutoffAngle" value="30"/>
        <float name="beamWidth" value="12"/>
        <transform name="toWorld"><lookat origin="0.3, 1.5, 0.2" target="0.6, 0, -0.1" up="0, 0, 1"/></transform>
      </emitter></scene>"""))
    scene = load(tmp_path)
    assert not any("spot" in m for m in scene.params["approximations"]), scene.params["approximations"]
    frame = PathTracer(max_depth=2).render(scene, 0, spp=2, channels={"position"}, resolution=(24, 24))
    position = frame["position"].astype(np.float64)
    floor = np.isfinite(position).all(axis=-1) & (np.abs(position[..., 1]) < 1e-4)
    apex = np.array([0.3, 1.5, 0.2])
    axis = np.array([0.6, 0.0, -0.1]) - apex
    axis /= np.linalg.norm(axis)
    to_point = position[floor] - apex
    d = np.linalg.norm(to_point, axis=-1)
    theta = np.arccos(np.clip(to_point @ axis / d, -1.0, 1.0))
    cutoff, beam = np.radians(30.0), np.radians(12.0)
    falloff = np.where(theta <= beam, 1.0, np.clip((cutoff - theta) / (cutoff - beam), 0.0, None))
    cos_s = -to_point[:, 1] / d
    expected = 0.5 / np.pi * np.array([4.0, 3.0, 2.0]) * (falloff * cos_s / d**2)[:, None]
    assert floor.sum() > 300 and (falloff == 1.0).sum() > 10 and ((falloff > 0) & (falloff < 1)).sum() > 10
    assert (falloff == 0).sum() > 10
    np.testing.assert_allclose(frame["color"].astype(np.float64)[floor], expected, rtol=1e-4, atol=1e-6)


def test_texture_lookup_wraps_and_blends_bilinearly():
    """tex_rgb against a NumPy restatement of the lookup (texel centres at (c + 0.5) / w and
    1 - (r + 0.5) / h, wrapping in both directions) at uv far outside [0, 1], on texel centres
    and on the wrap seams, with a uv scale and offset."""
    from plugins.renderers.pathtracer.shading import tex_rgb

    rng = np.random.default_rng(5)
    h, w = 3, 5
    img = rng.random((h, w, 3)).astype(np.float32)
    data = np.concatenate([np.zeros(6, np.float32), img.ravel()])  # a second texture's data first
    off, tw, th = np.array([0, 6]), np.array([2, w], np.int32), np.array([1, h], np.int32)
    uv = np.array([[1.0, 1.0, 0.0, 0.0], [1.5, 0.75, 0.25, -0.5]])
    us = np.concatenate([rng.uniform(-2.3, 3.7, 60), (np.arange(w) + 0.5) / w, [0.0, 1.0, -1.0, 2.0]])
    vs = np.concatenate([rng.uniform(-2.3, 3.7, 60), (np.arange(w) + 0.5) / h, [0.0, 1.0, 2.0, -1.0]])
    for u, v in zip(us, vs):
        x = (u * 1.5 + 0.25) % 1.0 * w - 0.5
        y = (1.0 - (v * 0.75 - 0.5) % 1.0) * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        i0, j0 = int(x0) % w, int(y0) % h
        i1, j1 = (i0 + 1) % w, (j0 + 1) % h
        want = ((1 - fy) * ((1 - fx) * img[j0, i0] + fx * img[j0, i1])
                + fy * ((1 - fx) * img[j1, i0] + fx * img[j1, i1]))
        got = tex_rgb(1, u, v, data, off, tw, th, uv)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
