"""The raster renderer's anti-aliasing inputs: the jitter cycle, the GGX sun lobe, metals, SSAA references."""

from __future__ import annotations

import numpy as np
import pytest

from harness import (
    JITTER_CYCLE,
    CameraPath,
    Environment,
    Material,
    Scene,
    SceneObject,
    Sun,
    halton_jitter,
    load_plugins,
)
from plugins.renderers.raster.shading import ggx_lobe, sun_irradiance


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def test_jitter_cycles_through_16_well_spread_points():
    points = np.array([halton_jitter(t) for t in range(JITTER_CYCLE)])
    assert JITTER_CYCLE == 16
    assert len({tuple(p) for p in points}) == 16
    assert (points >= -0.5).all() and (points < 0.5).all()
    assert halton_jitter(16) == halton_jitter(0) and halton_jitter(35) == halton_jitter(3)
    # stratified: one point in each quarter of the pixel per 4 consecutive points of base 2 in x,
    # and the cycle's mean is close to the pixel centre
    assert np.abs(points.mean(axis=0)).max() < 0.05
    for q in range(4):
        xs = points[4 * q:4 * q + 4, 0]
        assert sorted(np.floor((xs + 0.5) * 4).astype(int)) == [0, 1, 2, 3]


def test_render_records_the_cycled_jitter(registry):
    scene = registry.get("scene", "aa-railing").factory()
    r = registry.get("renderer", "raster").factory(jitter=True)
    for t in (0, 5, 16, 17):
        assert r.render(scene, t, resolution=(16, 9)).meta.jitter == halton_jitter(t)


def _lobe(n_l, n_v, n_h, v_h, alpha):
    return ggx_lobe.py_func(n_l, n_v, n_h, v_h, alpha)


def test_ggx_lobe_is_reciprocal_peaked_and_conserves_energy():
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.uniform(0.05, 0.8)
        n_l, n_v = rng.uniform(0.05, 1.0, 2)
        n_h, v_h = rng.uniform(0.0, 1.0, 2)
        # BRDF = lobe / n_l is symmetric in (l, v)
        assert np.isclose(_lobe(n_l, n_v, n_h, v_h, a) / n_l, _lobe(n_v, n_l, n_h, v_h, a) / n_v, rtol=1e-12)
    assert _lobe(-0.1, 0.5, 1.0, 1.0, 0.2) == 0.0 and _lobe(0.5, 0.0, 1.0, 1.0, 0.2) == 0.0
    assert _lobe(0.7, 0.7, 1.0, 0.7, 0.1) > 50 * _lobe(0.7, 0.7, 0.9, 0.7, 0.1)
    # directional albedo at normal view: integral of the lobe over the hemisphere of lights <= 1
    for alpha in (0.05, 0.2, 0.6):
        theta = (np.arange(4000) + 0.5) / 4000 * np.pi / 2
        n_l = np.cos(theta)
        n_h = np.cos(theta / 2)  # view along the normal: h halfway between n and l
        lobe = np.array([_lobe(c, 1.0, h, h, alpha) for c, h in zip(n_l, n_h)])
        albedo = np.sum(lobe * np.sin(theta)) * (np.pi / 2 / 4000) * 2 * np.pi
        assert 0.5 < albedo <= 1.0 + 1e-3, (alpha, albedo)


def _sphere_scene(kind: str, roughness: float, environment=None) -> Scene:
    import pyvista as pv

    mesh = pv.Sphere(radius=1.0, theta_resolution=96, phi_resolution=96)
    mesh.point_data["normal"] = np.asarray(mesh.points / np.linalg.norm(mesh.points, axis=1, keepdims=True),
                                           np.float32)
    material = Material("m", kind=kind, albedo=(0.5, 0.5, 0.5), specular=(0.9, 0.9, 0.9), roughness=roughness)
    camera = CameraPath(positions=[(0.0, 0.0, 4.0)], targets=[(0.0, 0.0, 0.0)], fov=40.0)
    sun = Sun(direction=(0.0, 0.0, 1.0), angular_radius=0.27, radiance=(1e4, 1e4, 1e4))
    return Scene("sphere", objects=[SceneObject("ball", mesh)], materials=[material], sun=sun,
                 environment=environment, camera=camera, resolution=(64, 64))


def test_glossy_sphere_has_a_highlight_facing_the_sun(registry):
    r = registry.get("renderer", "raster").factory(jitter=False)
    frame = r.render(_sphere_scene("plastic", 0.1), 0, channels={"normal"})
    lum = frame["color"].mean(axis=-1)
    i, j = np.unravel_index(np.argmax(lum), lum.shape)
    # the sun is behind the camera: the highlight sits where the normal faces the viewer
    assert frame["normal"][i, j, 2] > 0.99
    diffuse = Scene("d", objects=_sphere_scene("diffuse", 0.1).objects,
                    materials=[Material("m", albedo=(0.5, 0.5, 0.5))], sun=_sphere_scene("plastic", 0.1).sun,
                    camera=_sphere_scene("plastic", 0.1).camera, resolution=(64, 64))
    plain = r.render(diffuse, 0)["color"].mean(axis=-1)
    assert lum.max() > 3.0 * plain.max()
    # the lobe only adds light, and little of it away from the highlight (GGX tails)
    assert (lum >= plain - 1e-6).all()
    far = (frame["normal"][..., 2] < 0.5) & (lum > 0)
    assert far.sum() > 50 and ((lum - plain)[far] < 0.25 * plain[far]).all()
    # the peak equals F D G / (4 n.v) E at n = v = l (D = 1 / (pi a^2), G = 1, F = F0)
    expected = 0.9 / (np.pi * 0.1**2) / 4.0 * float(sun_irradiance(_sphere_scene("plastic", 0.1).sun)[0])
    assert lum.max() <= plain.max() + expected * 1.001
    assert lum.max() > plain.max() + expected * 0.8  # pixel centres miss n = v = l by ~0.3 degrees


def test_metal_reflects_the_environment_and_has_no_diffuse_term(registry):
    env = Environment(kind="sky", radiance=(0.0, 0.0, 1.0), horizon=(1.0, 0.0, 0.0))
    scene = _sphere_scene("conductor", 0.3, env)
    scene.sun = None
    r = registry.get("renderer", "raster").factory(jitter=False)
    frame = r.render(scene, 0, channels={"normal", "object_id"})
    c, n = frame["color"], frame["normal"].astype(np.float64)
    on = frame["object_id"] >= 0
    # colour = Schlick Fresnel x the sky seen in the mirror direction (blue zenith, red horizon)
    _, d = scene.camera.primary_rays(0, 64, 64)
    n_v = np.clip(-(n * d).sum(axis=-1, keepdims=True), 0.0, 1.0)
    reflected = d + 2.0 * n_v * n
    t = np.clip(reflected[..., 1:2], 0.0, 1.0)
    sky = (1.0 - t) * np.array([1.0, 0.0, 0.0]) + t * np.array([0.0, 0.0, 1.0])
    expected = (0.9 + 0.1 * (1.0 - n_v) ** 5) * sky
    np.testing.assert_allclose(c[on], expected[on], atol=2e-5)
    assert (c[on][:, 2] > 0.5).any() and (c[on][:, 0] > 0.5).any()


def test_ssaa_reference_defaults_to_8x8_box(registry):
    spec = registry.get("renderer", "raster")
    assert spec.reference_spp == 64 and "antialias" in spec.tasks
    scene = registry.get("scene", "aa-fence").factory()
    r = spec.factory(jitter=False)
    w, h = 24, 14
    ref = r.reference(scene, 3, resolution=(w, h))
    big = r.render(scene, 3, resolution=(8 * w, 8 * h))["color"]
    np.testing.assert_allclose(big.reshape(h, 8, w, 8, 3).mean(axis=(1, 3)), ref, rtol=1e-5, atol=1e-6)
    # the reference is unjittered whatever the renderer's jitter setting
    np.testing.assert_array_equal(spec.factory().reference(scene, 3, resolution=(w, h)), ref)
