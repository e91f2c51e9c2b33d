"""The built-in scene suite: registration, geometry sanity, determinism, scene-specific facts."""

from __future__ import annotations

import numpy as np
import pytest

from harness import Scene, load_plugins

SUITE = ("cornell", "atrium", "courtyard", "street", "furnace")


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def scenes(registry):
    return {name: registry.get("scene", name).factory() for name in SUITE}


def test_suite_registered_with_declarations_matching_scenes(registry, scenes):
    for name in SUITE:
        spec = registry.get("scene", name)
        scene = scenes[name]
        assert isinstance(scene, Scene) and scene.kind == "mesh" == spec.kind
        assert spec.suite == (name != "furnace")  # every pixel of the furnace is an emitter
        assert scene.name == name
        assert scene.frame_count == spec.frames
        assert tuple(scene.resolution) == spec.resolution
        assert scene.tags == spec.tags
        w, h = spec.resolution
        assert w * h <= 192 * 128, "default resolutions stay small (the suite is path traced on a laptop)"


def test_geometry_is_well_formed(scenes):
    for name, scene in scenes.items():
        soup = scene.triangles(0)
        count = len(soup.vertices)
        assert 0 < count <= 50_000, (name, count)
        assert np.isfinite(soup.vertices).all()
        assert soup.material.min() >= 0 and soup.material.max() < len(scene.materials), name
        lengths = np.linalg.norm(soup.normals, axis=-1)
        np.testing.assert_allclose(lengths, 1.0, atol=1e-4, err_msg=name)
        area = np.linalg.norm(np.cross(soup.vertices[:, 1] - soup.vertices[:, 0],
                                       soup.vertices[:, 2] - soup.vertices[:, 0]), axis=1)
        assert area.min() > 0.0, f"{name} has degenerate triangles"
        for obj in scene.objects:
            assert "uv" in obj.mesh.point_data and "material" in obj.mesh.cell_data, (name, obj.name)


def test_content_hash_is_stable_and_distinct(registry, scenes):
    hashes = {name: scene.content_hash() for name, scene in scenes.items()}
    assert len(set(hashes.values())) == len(SUITE)
    for name in ("cornell", "courtyard"):
        assert registry.get("scene", name).factory().content_hash() == hashes[name]


def test_tags_cover_what_filters_get_wrong(scenes):
    assert {"foliage", "cloth", "hard_shadows", "dark_regions"} <= scenes["atrium"].tags
    assert {"foliage", "glossy", "many_objects"} <= scenes["courtyard"].tags
    assert {"dynamic", "disocclusion", "glossy"} <= scenes["street"].tags
    assert "soft_shadows" in scenes["cornell"].tags
    emissive = [m for m in scenes["cornell"].materials if m.is_emissive]
    assert len(emissive) == 1
    assert scenes["atrium"].sun is not None and scenes["atrium"].environment is not None
    glossy = [m for m in scenes["courtyard"].materials if m.kind in ("plastic", "conductor") and m.roughness < 0.1]
    assert glossy


def test_furnace_is_a_closed_inward_sphere_with_documented_answer(scenes):
    scene = scenes["furnace"]
    rho, le = scene.params["rho"], scene.params["Le"]
    assert scene.params["expected_radiance"] == pytest.approx(le / (1 - rho))
    (material,) = scene.materials
    assert material.albedo == (rho,) * 3 and material.emission == (le,) * 3
    soup = scene.triangles(0)
    centroid = soup.vertices.mean(axis=1)
    geometric = np.cross(soup.vertices[:, 1] - soup.vertices[:, 0], soup.vertices[:, 2] - soup.vertices[:, 0])
    assert ((geometric * centroid).sum(axis=1) < 0).all(), "winding must face the centre"
    assert ((soup.normals * soup.vertices).sum(axis=-1) < 0).all(), "shading normals must face the centre"
    # closed: every edge (corners identified by position) is shared by exactly two triangles
    keys = np.round(soup.vertices.astype(np.float64), 5)
    _, corner = np.unique(keys.reshape(-1, 3), axis=0, return_inverse=True)
    corner = corner.reshape(-1, 3)
    edges = np.sort(np.concatenate([corner[:, [0, 1]], corner[:, [1, 2]], corner[:, [2, 0]]]), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert (uses == 2).all()
    assert np.linalg.norm(scene.camera.eye(0)) < 0.5


def test_street_is_a_sequence_with_moving_camera_and_object(scenes):
    scene = scenes["street"]
    assert scene.frame_count >= 16
    assert not np.allclose(scene.camera.eye(0), scene.camera.eye(scene.frame_count - 1))
    moving = [obj for obj in scene.objects if obj.transforms is not None]
    assert moving
    car = next(obj for obj in moving if obj.name == "car")
    assert not np.allclose(car.transform(0), car.transform(scene.frame_count - 1))
    first, last = scene.triangles(0), scene.triangles(scene.frame_count - 1)
    assert first.vertices.shape == last.vertices.shape
    assert not np.allclose(first.vertices, last.vertices)
