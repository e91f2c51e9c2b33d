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
