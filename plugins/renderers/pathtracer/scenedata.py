"""A :class:`harness.Scene` frame flattened to the structure-of-arrays the kernels read."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness import Material, Scene, read_texture

from . import lights as L
from .bvh import build_bvh, pack_wide
from .materials import ONE_SIDED_EMISSION, MaterialTables, compile_materials

_ENV_CODES = {"constant": L.ENV_CONSTANT, "sky": L.ENV_SKY, "map": L.ENV_MAP}


def _lum(rgb) -> float:
    r, g, b = (float(v) for v in rgb)
    return 0.2126 * r + 0.7152 * g + 0.0722 * b


@dataclass
class SceneData:
    """Arrays of one frame of a mesh scene, in BVH order.

    Attributes
    ----------
    tri_v, tri_n : ndarray (T, 9) float32
        Corner positions and shading normals ``(v0, v1, v2)``.
    tri_uv : ndarray (T, 6) float32
    tri_mat, tri_obj : ndarray (T,) int32
    tri_front : ndarray (T,) float64
        +1 where the winding normal agrees with the triangle's shading normals, else -1 (the
        emitting side of one-sided emitters).
    nodes_f, nodes_i : the BVH (see :func:`.bvh.pack_wide`); ``depth`` its number of levels.
    mats : MaterialTables
        Materials and textures (see :mod:`.materials`).
    emit_tri, emit_cdf, tri_light_pdf, lp, env_img, cdf_rows, cdf_cols : lights (see :mod:`.lights`).
    eps : float
        Ray-origin offset along the geometric normal, relative to the scene's extent.
    """

    tri_v: np.ndarray
    tri_n: np.ndarray
    tri_uv: np.ndarray
    tri_mat: np.ndarray
    tri_obj: np.ndarray
    tri_front: np.ndarray
    nodes_f: np.ndarray
    nodes_i: np.ndarray
    depth: int
    mats: MaterialTables
    emit_tri: np.ndarray
    emit_cdf: np.ndarray
    tri_light_pdf: np.ndarray
    lp: np.ndarray
    env_img: np.ndarray
    cdf_rows: np.ndarray
    cdf_cols: np.ndarray
    eps: float

    @property
    def mat_emit(self) -> np.ndarray:
        return self.mats.mat_emit

    def geometry(self) -> tuple:
        """Arrays the traversal and surface lookups need."""
        return (self.tri_v, self.tri_n, self.tri_uv, self.tri_mat, self.nodes_f, self.nodes_i, self.tri_front)

    def materials(self) -> tuple:
        """Material and texture arrays."""
        return self.mats.arrays()

    def lights(self) -> tuple:
        """Light-sampling arrays (``lp`` is passed separately)."""
        return (self.emit_tri, self.emit_cdf, self.tri_light_pdf, self.env_img, self.cdf_rows, self.cdf_cols)


def _environment(scene: Scene):
    env = scene.environment
    if env is None or env.kind != "map" or env.image is None:
        return np.zeros((1, 1, 3), np.float32), np.array([0.0, 1.0]), np.array([[0.0, 1.0]])
    img = env.image if isinstance(env.image, np.ndarray) else read_texture(env.image)
    img = np.ascontiguousarray(np.clip(np.nan_to_num(np.asarray(img, np.float32)[..., :3], nan=0.0), 0.0, None))
    rows, cols = L.environment_tables(img)
    return img, rows, cols


def _env_integral(scene: Scene, env_img: np.ndarray) -> float:
    """Integral of the environment's luminance over the sphere of directions."""
    env = scene.environment
    if env is None:
        return 0.0
    if env.kind == "constant":
        return 4.0 * math.pi * max(_lum(env.radiance), 0.0)
    if env.kind == "sky":
        return max(4.0 * math.pi * _lum(env.horizon) + math.pi * (_lum(env.radiance) - _lum(env.horizon)), 0.0)
    if env.image is None:
        return 0.0
    h = env_img.shape[0]
    sin_t = np.sin((np.arange(h) + 0.5) / h * np.pi)
    mean = float((L.luminance_image(env_img) * sin_t[:, None]).mean())
    return 2.0 * math.pi * math.pi * mean * max(_lum(env.radiance), 0.0)


def build_scene_data(scene: Scene, frame: int) -> SceneData:
    """Flatten ``scene`` at ``frame``, build its BVH and light tables.

    Parameters
    ----------
    scene : harness.Scene
        A ``mesh`` scene.
    frame : int

    Returns
    -------
    SceneData
    """
    soup = scene.triangles(frame)
    verts = np.asarray(soup.vertices, np.float32)
    norms = np.asarray(soup.normals, np.float32)
    uvs = np.asarray(soup.uvs, np.float32)
    tmat = np.asarray(soup.material, np.int32)
    tobj = np.asarray(soup.object_id, np.int32)
    mats = compile_materials(list(scene.materials) or [Material("default")], scene.params.get("bsdfs"))
    n_mat = len(mats.mat_root)
    if len(verts) == 0:
        verts = np.zeros((1, 3, 3), np.float32)
        norms = np.zeros((1, 3, 3), np.float32)
        norms[..., 2] = 1.0
        uvs = np.zeros((1, 3, 2), np.float32)
        tmat = np.zeros(1, np.int32)
        tobj = np.zeros(1, np.int32)
    if tmat.min() < 0 or tmat.max() >= n_mat:
        raise ValueError(f"pathtracer: scene {scene.name!r} uses material index {int(tmat.max())} "
                         f"but has {n_mat} materials")
    bounds, child, count, order, depth = build_bvh(verts)
    nodes_f, nodes_i = pack_wide(bounds, child, count)
    verts, norms, uvs, tmat, tobj = verts[order], norms[order], uvs[order], tmat[order], tobj[order]
    tri_v = np.ascontiguousarray(verts.reshape(-1, 9))
    tri_n = np.ascontiguousarray(norms.reshape(-1, 9))
    tri_uv = np.ascontiguousarray(uvs.reshape(-1, 6))
    e32 = verts.astype(np.float64)
    winding = np.cross(e32[:, 1] - e32[:, 0], e32[:, 2] - e32[:, 0])
    tri_front = np.where(np.einsum("ij,ij->i", winding, norms.astype(np.float64).sum(axis=1)) < 0.0, -1.0, 1.0)

    lo = verts.reshape(-1, 3).min(axis=0).astype(np.float64)
    hi = verts.reshape(-1, 3).max(axis=0).astype(np.float64)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
    extent = float(np.abs(np.concatenate([lo, hi])).max())
    eps = 1e-6 * (1.0 + extent)

    # emissive triangles, in proportion to power (one face or both)
    area = 0.5 * np.linalg.norm(winding, axis=1)
    emit = mats.mat_emit[tmat].astype(np.float64)
    sides = np.where(mats.mat_flags[tmat] & ONE_SIDED_EMISSION, 1.0, 2.0)
    power = sides * math.pi * area * np.maximum(emit @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    emitters = np.flatnonzero((power > 0) & (area > 0)).astype(np.int32)
    tri_power = float(power[emitters].sum())

    env_img, cdf_rows, cdf_cols = _environment(scene)
    lp = np.zeros(L.N_PARAMS)
    lp[L.SUN_COS] = 1.0
    lp[L.ENV_KIND] = L.ENV_NONE
    sun_power = env_power = 0.0
    far = math.pi * radius * radius
    if scene.sun is not None and _lum(scene.sun.radiance) > 0:
        radius_deg = max(float(scene.sun.angular_radius), L.MIN_SUN_RADIUS_DEG)
        cos_max = math.cos(math.radians(radius_deg))
        lp[L.SUN_DIR:L.SUN_DIR + 3] = scene.sun.direction
        lp[L.SUN_COS] = cos_max
        lp[L.SUN_RAD:L.SUN_RAD + 3] = scene.sun.radiance
        sun_power = far * _lum(scene.sun.radiance) * 2.0 * math.pi * (1.0 - cos_max)
    if scene.environment is not None:
        env = scene.environment
        lp[L.ENV_KIND] = _ENV_CODES[env.kind]
        lp[L.ENV_RAD:L.ENV_RAD + 3] = env.radiance
        lp[L.ENV_HORIZON:L.ENV_HORIZON + 3] = env.horizon
        lp[L.ENV_ROT] = math.radians(env.rotation)
        env_power = far * _env_integral(scene, env_img)
    delta, delta_each = L.delta_light_params(scene.params.get("delta_lights") or [])
    delta_power = float(delta_each.sum())
    total = tri_power + sun_power + env_power + delta_power
    if total > 0:
        lp[L.P_TRI] = tri_power / total
        lp[L.P_SUN] = sun_power / total
        lp[L.P_ENV] = env_power / total
        lp[L.P_DELTA] = delta_power / total
    if delta_power > 0:
        cdf = np.cumsum(delta_each) / delta_power
        cdf[-1] = 1.0
        delta[L.D_CDF::L.DELTA_STRIDE] = cdf
        lp[L.N_DELTA] = len(delta_each)
        lp = np.concatenate([lp, delta])
    tri_light_pdf = np.zeros(len(tri_v))
    if tri_power > 0:
        p_each = power[emitters] / tri_power
        emit_cdf = np.concatenate([[0.0], np.cumsum(p_each)])
        emit_cdf[-1] = 1.0
        tri_light_pdf[emitters] = lp[L.P_TRI] * p_each / area[emitters]
    else:
        emit_cdf = np.array([0.0, 1.0])
        emitters = np.zeros(1, np.int32)
    return SceneData(tri_v, tri_n, tri_uv, tmat, tobj, tri_front, nodes_f, nodes_i, int(depth), mats,
                     emitters, emit_cdf, tri_light_pdf, lp, env_img, cdf_rows, cdf_cols, eps)
