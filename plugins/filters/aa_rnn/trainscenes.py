"""Random procedural scenes for training ``aa_rnn``, generated for training only.

Each scene is drawn from a seed: a textured ground plane (checkerboards, stripes or random
bit-blocks at random scales, so that it is minified somewhere), sometimes a textured back wall,
and 6 to 14 random objects: spheres and tori (glossy plastic, metal or diffuse), boxes, fences of
thin bars, overhead wires and tufts of grass blades, built from PyVista's own primitives. A sun
at a random elevation and a random sky light it. The camera is static (a fifth of the scenes) or
moves by up to 2 m over the sequence while 1 or 2 objects move and turn. None of this shares code
or parameters with the benchmark's ``antialias`` scenes (``plugins/scenes/antialias``), which are
never used for training (``tests/test_aa_rnn.py`` checks that no generated scene equals one).
"""

from __future__ import annotations

import numpy as np

from harness import CameraPath, Environment, Material, Scene, SceneObject, Sun, rotation, translation

#: name prefix of every generated scene
PREFIX = "aa_rnn-train"


def _texture(rng: np.random.Generator) -> np.ndarray:
    """A random high-frequency albedo texture (64 x 64, linear RGB in [0.03, 0.9])."""
    kind = rng.integers(4)
    size = 64
    a, b = rng.uniform(0.03, 0.9, 3), rng.uniform(0.03, 0.9, 3)
    idx = np.arange(size)
    if kind == 0:  # checkerboard
        n = int(rng.choice([2, 4, 8, 16]))
        cell = idx * n // size
        mask = (cell[:, None] + cell[None, :]) % 2 == 1
    elif kind == 1:  # stripes, straight or diagonal
        n = int(rng.choice([4, 8, 16]))
        mask = ((idx[:, None] * rng.integers(2) + idx[None, :]) * n // size) % 2 == 0
    elif kind == 2:  # random bit-blocks (text-like)
        n = int(rng.choice([16, 32, 64]))
        bits = rng.random((n, n)) < rng.uniform(0.2, 0.6)
        mask = bits[idx * n // size][:, idx * n // size]
    else:  # smooth blobs (no aliasing: the network must keep such detail)
        n = 4
        lattice = rng.random((n, n))
        mask = lattice[idx * n // size][:, idx * n // size] > 0.5
    return np.where(mask[..., None], a, b).astype(np.float32)


def _finish(mesh, uv_scale: float = 1.0):
    """Triangulated PolyData with point data ``normal`` and ``uv`` (sphere-mapped where missing)."""
    mesh = mesh.triangulate().compute_normals(split_vertices=True, feature_angle=40.0, auto_orient_normals=False,
                                              consistent_normals=False)
    uv = mesh.active_texture_coordinates
    if uv is None:
        uv = mesh.texture_map_to_sphere(prevent_seam=False).active_texture_coordinates
    mesh.point_data["uv"] = (np.asarray(uv, np.float32) * uv_scale).astype(np.float32)
    mesh.point_data["normal"] = np.asarray(mesh.point_data["Normals"], np.float32)
    for key in [k for k in mesh.point_data.keys() if k not in ("uv", "normal")]:
        del mesh.point_data[key]
    for key in list(mesh.cell_data.keys()):
        del mesh.cell_data[key]
    return mesh


def _material(rng: np.random.Generator, name: str, textured: bool) -> Material:
    kind = rng.choice(["diffuse", "plastic", "conductor"], p=[0.45, 0.35, 0.2])
    texture = _texture(rng) if textured else None
    if kind == "conductor":
        return Material(name, kind="conductor", specular=tuple(rng.uniform(0.5, 0.95, 3)),
                        roughness=float(rng.uniform(0.04, 0.3)))
    albedo = tuple(rng.uniform(0.05, 0.85, 3)) if texture is None else (1.0, 1.0, 1.0)
    return Material(name, kind=str(kind), albedo=albedo, texture=texture, roughness=float(rng.uniform(0.04, 0.4)))


def _bars(rng: np.random.Generator, pv):
    """A fence or railing: 8 to 40 parallel thin bars on a line."""
    count = int(rng.integers(8, 41))
    radius = float(rng.uniform(0.004, 0.03))
    spacing = float(rng.uniform(0.05, 0.3))
    height = float(rng.uniform(0.5, 2.0))
    vertical = rng.random() < 0.7
    parts = []
    for k in range(count):
        offset = (k - count / 2) * spacing
        if vertical:
            centre, direction = (offset, height / 2, 0.0), (0.0, 1.0, 0.0)
        else:
            centre, direction = (0.0, 0.1 + offset * 0.5 + count * spacing * 0.25, 0.0), (1.0, 0.0, 0.0)
        parts.append(pv.Cylinder(center=centre, direction=direction, radius=radius,
                                 height=height if vertical else count * spacing, resolution=6, capping=False))
    return pv.merge(parts)


def _wires(rng: np.random.Generator, pv):
    """2 to 6 long thin wires high up."""
    parts = []
    for _ in range(int(rng.integers(2, 7))):
        y = float(rng.uniform(2.0, 8.0))
        z = float(rng.uniform(-25.0, -3.0))
        angle = float(rng.uniform(-0.4, 0.4))
        parts.append(pv.Cylinder(center=(0.0, y, z), direction=(np.cos(angle), np.sin(angle) * 0.3, np.sin(angle)),
                                 radius=float(rng.uniform(0.005, 0.03)), height=60.0, resolution=5, capping=False))
    return pv.merge(parts)


def _grass(rng: np.random.Generator, pv):
    """50 to 300 thin triangles standing on the ground."""
    count = int(rng.integers(50, 301))
    spread = float(rng.uniform(0.5, 2.0))
    points, faces = [], []
    for _ in range(count):
        x, z = rng.uniform(-spread, spread, 2)
        w = rng.uniform(0.005, 0.02)
        h = rng.uniform(0.1, 0.5)
        lean = rng.normal(0.0, 0.05, 2)
        base = len(points)
        points += [(x - w, 0.0, z), (x + w, 0.0, z), (x + lean[0], h, z + lean[1])]
        faces.append([3, base, base + 1, base + 2])
    return pv.PolyData(np.asarray(points, np.float32), faces=np.asarray(faces).ravel())


def _shape(rng: np.random.Generator, pv):
    """One random object (PolyData before :func:`_finish`), its kind and whether to texture it."""
    kind = rng.choice(["sphere", "torus", "box", "bars", "wires", "grass"], p=[0.25, 0.1, 0.2, 0.2, 0.1, 0.15])
    if kind == "sphere":
        return pv.Sphere(radius=float(rng.uniform(0.15, 1.2)), theta_resolution=32, phi_resolution=24), kind, True
    if kind == "torus":
        r = float(rng.uniform(0.2, 0.8))
        torus = pv.ParametricTorus(ringradius=r, crosssectionradius=r * float(rng.uniform(0.1, 0.35)), u_res=40,
                                   v_res=16, w_res=2)
        return torus, kind, False
    if kind == "box":
        size = rng.uniform(0.1, 2.0, 3)
        return pv.Box(bounds=(-size[0] / 2, size[0] / 2, 0.0, size[1], -size[2] / 2, size[2] / 2)), kind, True
    if kind == "bars":
        return _bars(rng, pv), kind, False
    if kind == "wires":
        return _wires(rng, pv), kind, False
    return _grass(rng, pv), kind, False


def make_scene(seed: int, frames: int, resolution: tuple) -> Scene:
    """The random training scene of ``seed`` (a fresh :class:`harness.Scene`).

    Parameters
    ----------
    seed : int
    frames : int
        Length of the sequence.
    resolution : (int, int)
        Default (width, height).
    """
    import pyvista as pv

    rng = np.random.default_rng(seed)
    materials = [_material(rng, "ground", textured=True)]
    ground = pv.Plane(center=(0.0, 0.0, -10.0), direction=(0.0, 1.0, 0.0), i_size=80.0, j_size=80.0)
    objects = [SceneObject("ground", _finish(ground, uv_scale=float(rng.uniform(10.0, 200.0))), material=0)]
    if rng.random() < 0.5:
        materials.append(_material(rng, "wall", textured=True))
        wall = pv.Plane(center=(0.0, 4.0, float(rng.uniform(-25.0, -8.0))), direction=(0.0, 0.0, 1.0),
                        i_size=40.0, j_size=8.0)
        objects.append(SceneObject("wall", _finish(wall, uv_scale=float(rng.uniform(2.0, 30.0))),
                                   material=len(materials) - 1))
    count = int(rng.integers(6, 15))
    moving = set(rng.choice(count, size=int(rng.integers(1, 3)), replace=False).tolist())
    for k in range(count):
        mesh, kind, textured = _shape(rng, pv)
        materials.append(_material(rng, f"m{k}", textured=textured and rng.random() < 0.6))
        position = np.array([rng.uniform(-4.0, 4.0), 0.0, rng.uniform(-6.0, 1.5)])
        if kind in ("sphere", "torus"):
            position[1] = rng.uniform(0.2, 2.0)
        spin = float(rng.uniform(0.0, 360.0))
        transforms = None
        if k in moving:
            velocity = rng.normal(0.0, 0.12, 3) * np.array([1.0, 0.2, 1.0])
            turn = float(rng.normal(0.0, 8.0))
            transforms = np.stack([translation(position + t * velocity) @ rotation((0.0, 1.0, 0.0), spin + t * turn)
                                   for t in range(frames)])
        else:
            mesh = mesh.transform(translation(position) @ rotation((0.0, 1.0, 0.0), spin), inplace=False)
        objects.append(SceneObject(f"{kind}{k}", _finish(mesh), material=len(materials) - 1, transforms=transforms))
    elevation = np.radians(rng.uniform(15.0, 75.0))
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    direction = (np.cos(elevation) * np.cos(azimuth), np.sin(elevation), np.cos(elevation) * np.sin(azimuth))
    solid_angle = 2.0 * np.pi * (1.0 - np.cos(np.radians(0.27)))
    sun = Sun(direction=direction, angular_radius=0.27, radiance=float(rng.uniform(1.2, 3.0)) / solid_angle)
    zenith = rng.uniform(0.05, 0.5, 3)
    sky = Environment(kind="sky", radiance=tuple(zenith), horizon=tuple(rng.uniform(0.2, 0.7, 3)))
    return Scene(name=f"{PREFIX}-{seed}", frame_count=frames, resolution=tuple(resolution), objects=objects,
                 materials=materials, sun=sun, environment=sky, camera=_camera(rng, frames), source=PREFIX,
                 tags=frozenset({"antialias", "training"}))


def _camera(rng: np.random.Generator, frames: int) -> CameraPath:
    """Static (a fifth of the scenes) or moving by up to 2 m, looking at the objects."""
    distance = rng.uniform(3.0, 7.0)
    angle = rng.uniform(-0.6, 0.6)
    eye = np.array([distance * np.sin(angle), rng.uniform(0.4, 3.0), 2.0 + distance * np.cos(angle)])
    target = np.array([rng.uniform(-2.0, 2.0), rng.uniform(0.0, 1.0), rng.uniform(-4.0, 0.0)])
    s = np.linspace(0.0, 1.0, frames)[:, None]
    if rng.random() < 0.2:
        move = np.zeros(3)
        look = np.zeros(3)
    else:
        move = rng.normal(0.0, 1.0, 3) * np.array([1.0, 0.2, 1.0])
        move *= rng.uniform(0.1, 2.0) / max(np.linalg.norm(move), 1e-9)
        look = rng.normal(0.0, 0.5, 3)
    return CameraPath(positions=eye + s * move, targets=target + s * look, fov=float(rng.uniform(40.0, 70.0)),
                      near=0.05, far=300.0)
