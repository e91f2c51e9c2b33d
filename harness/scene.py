"""The scene model shared by scene plugins and renderers.

A :class:`Scene` is ``procedural`` (a named pattern with parameters, understood by the
``synthetic`` renderer), ``mesh`` (PyVista meshes with materials, lights and a camera path,
understood by the raster renderer and the path tracer) or ``captured`` (frames another renderer
wrote, read by the ``captured`` renderer). Everything a renderer needs is in the
scene, and :meth:`Scene.content_hash` covers all of it, so cached renders miss when any input
changes.

Conventions: right-handed world, y up; lengths in scene units; angles in degrees at the API;
radiance in linear RGB.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

MATERIAL_KINDS = ("diffuse", "conductor", "plastic", "dielectric", "mirror")


@dataclass(frozen=True)
class Material:
    """A surface material.

    Attributes
    ----------
    name : str
    kind : {"diffuse", "conductor", "plastic", "dielectric", "mirror"}
        ``plastic`` is a diffuse base under a GGX dielectric coat; ``conductor`` is a GGX metal
        with reflectance ``specular``; ``mirror`` is a perfect conductor; ``dielectric`` is a
        smooth glass with index ``ior``.
    albedo : (float, float, float)
        Diffuse reflectance (multiplied by the texture, when there is one).
    texture : str, ndarray or None
        Albedo texture: an image path (read with OpenImageIO, linearised from sRGB when 8-bit)
        or an (h, w, 3) float32 array; looked up with the mesh's ``uv`` point data.
    emission : (float, float, float)
        Emitted radiance; non-zero makes the surface an area light.
    roughness : float
        GGX alpha (not squared) of the specular lobe.
    specular : (float, float, float)
        Normal-incidence reflectance F0 of the specular lobe.
    ior : float
        Index of refraction (dielectric, plastic coat).
    """

    name: str
    kind: str = "diffuse"
    albedo: tuple = (0.8, 0.8, 0.8)
    texture: Any = field(default=None, compare=False)
    emission: tuple = (0.0, 0.0, 0.0)
    roughness: float = 0.3
    specular: tuple = (0.04, 0.04, 0.04)
    ior: float = 1.5

    def __post_init__(self):
        if self.kind not in MATERIAL_KINDS:
            raise ValueError(f"material {self.name!r}: kind must be one of {MATERIAL_KINDS}, got {self.kind!r}")
        for attr in ("albedo", "emission", "specular"):
            value = tuple(float(v) for v in np.broadcast_to(np.asarray(getattr(self, attr), float), 3))
            object.__setattr__(self, attr, value)

    @property
    def is_emissive(self) -> bool:
        return max(self.emission) > 0.0

    def texture_array(self) -> np.ndarray | None:
        """The albedo texture as an (h, w, 3) float32 linear array, or None."""
        if self.texture is None:
            return None
        if isinstance(self.texture, np.ndarray):
            return np.ascontiguousarray(self.texture[..., :3], dtype=np.float32)
        return read_texture(self.texture)


def read_texture(path: str | Path) -> np.ndarray:
    """Read an image as a linear float32 (h, w, 3) array with OpenImageIO.

    8-bit images are taken as sRGB-encoded and linearised; float images are used as stored.
    """
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise FileNotFoundError(f"cannot read texture {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        is_float = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
    finally:
        inp.close()
    pixels = np.asarray(pixels, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    if spec.nchannels == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    elif spec.nchannels == 2:
        pixels = np.repeat(pixels[..., :1], 3, axis=2)
    pixels = pixels[..., :3]
    if not is_float:
        pixels = srgb_to_linear(pixels)
    return np.ascontiguousarray(pixels, dtype=np.float32)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB electro-optical transfer function, elementwise."""
    x = np.asarray(x, dtype=np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


@dataclass(frozen=True)
class Sun:
    """A distant disc light.

    Attributes
    ----------
    direction : (float, float, float)
        Unit vector from the scene towards the sun.
    angular_radius : float
        Half-angle of the disc, degrees (0.27 for the real sun).
    radiance : (float, float, float)
        Radiance of the disc.
    """

    direction: tuple = (0.3, 1.0, 0.2)
    angular_radius: float = 0.27
    radiance: tuple = (1000.0, 950.0, 900.0)

    def __post_init__(self):
        d = np.asarray(self.direction, float)
        d = d / max(np.linalg.norm(d), 1e-12)
        object.__setattr__(self, "direction", tuple(float(v) for v in d))
        object.__setattr__(self, "radiance", tuple(float(v) for v in np.broadcast_to(self.radiance, 3)))


@dataclass(frozen=True)
class Environment:
    """Light from infinitely far away.

    Attributes
    ----------
    kind : {"constant", "sky", "map"}
        ``sky`` is a simple gradient from ``horizon`` to ``radiance`` at the zenith;
        ``map`` is an equirectangular image (``image``: path or (h, w, 3) array).
    radiance : (float, float, float)
        Constant radiance, or zenith radiance for ``sky``; a multiplier for ``map``.
    horizon : (float, float, float)
        Horizon radiance of ``sky``.
    image : str, ndarray or None
    rotation : float
        Rotation of the map about the world y axis, degrees.
    """

    kind: str = "constant"
    radiance: tuple = (1.0, 1.0, 1.0)
    horizon: tuple = (1.0, 1.0, 1.0)
    image: Any = field(default=None, compare=False)
    rotation: float = 0.0

    def __post_init__(self):
        if self.kind not in ("constant", "sky", "map"):
            raise ValueError(f"environment kind must be constant, sky or map, got {self.kind!r}")
        for attr in ("radiance", "horizon"):
            object.__setattr__(self, attr, tuple(float(v) for v in np.broadcast_to(getattr(self, attr), 3)))

    def image_array(self) -> np.ndarray | None:
        """The ``map`` image as an (h, w, 3) float32 linear array (EXR/HDR read with OpenImageIO), or None."""
        if self.image is None:
            return None
        if isinstance(self.image, np.ndarray):
            return np.ascontiguousarray(self.image[..., :3], dtype=np.float32)
        return read_texture(self.image)


@dataclass
class CameraPath:
    """A perspective pinhole camera over the frames of a sequence.

    Attributes
    ----------
    positions : ndarray (F, 3)
        Eye position per frame (one row for a static camera).
    targets : ndarray (F, 3)
        Look-at point per frame.
    up : (float, float, float)
    fov : float
        Vertical field of view, degrees.
    near, far : float
        Clip distances used for projection matrices.
    ups : ndarray (F, 3) or None
        Up vector per frame (an animated roll); None: ``up`` on every frame. When given,
        ``up`` is set to its first row.
    fovs : ndarray (F,) or None
        Vertical field of view per frame, degrees (an animated zoom); None: ``fov`` on every
        frame. When given, ``fov`` is set to its first value.

    Every per-frame array repeats its last row past its end. Use :meth:`up_at` and
    :meth:`fov_at` for a frame's values.
    """

    positions: np.ndarray
    targets: np.ndarray
    up: tuple = (0.0, 1.0, 0.0)
    fov: float = 45.0
    near: float = 0.01
    far: float = 1000.0
    ups: np.ndarray | None = None
    fovs: np.ndarray | None = None

    def __post_init__(self):
        self.positions = np.atleast_2d(np.asarray(self.positions, np.float64))
        self.targets = np.atleast_2d(np.asarray(self.targets, np.float64))
        if self.positions.shape[1] != 3 or self.targets.shape[1] != 3:
            raise ValueError("camera positions and targets must be (F, 3)")
        if self.ups is not None:
            self.ups = np.atleast_2d(np.asarray(self.ups, np.float64))
            if self.ups.shape[1] != 3 or len(self.ups) == 0:
                raise ValueError("camera ups must be (F, 3)")
            self.up = tuple(float(v) for v in self.ups[0])
        if self.fovs is not None:
            self.fovs = np.atleast_1d(np.asarray(self.fovs, np.float64)).ravel()
            if len(self.fovs) == 0 or not ((self.fovs > 0) & (self.fovs < 180)).all():
                raise ValueError("camera fovs must be degrees in (0, 180)")
            self.fov = float(self.fovs[0])

    def _row(self, array: np.ndarray, frame: int) -> np.ndarray:
        return array[min(frame, len(array) - 1)]

    def eye(self, frame: int) -> np.ndarray:
        return self._row(self.positions, frame)

    def up_at(self, frame: int) -> np.ndarray:
        """The up vector of ``frame`` (not orthogonalised; :meth:`basis` does that)."""
        return np.asarray(self.up, float) if self.ups is None else self._row(self.ups, frame)

    def fov_at(self, frame: int) -> float:
        """The vertical field of view of ``frame``, degrees."""
        return float(self.fov) if self.fovs is None else float(self._row(self.fovs, frame))

    def basis(self, frame: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera (right, up, forward) unit vectors in world space for ``frame``."""
        eye = self.eye(frame)
        forward = self._row(self.targets, frame) - eye
        forward = forward / max(np.linalg.norm(forward), 1e-12)
        right = np.cross(forward, self.up_at(frame))
        if np.linalg.norm(right) < 1e-9:
            right = np.cross(forward, np.array([0.0, 0.0, 1.0]))
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        return right, up, forward

    def view_matrix(self, frame: int) -> np.ndarray:
        """World-to-view matrix (OpenGL convention: camera looks down -z)."""
        right, up, forward = self.basis(frame)
        eye = self.eye(frame)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = right, up, -forward
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection_matrix(self, width: int, height: int, jitter=(0.0, 0.0), frame: int | None = None) -> np.ndarray:
        """OpenGL perspective matrix (of ``frame``'s field of view; ``fov`` where None).

        With ``jitter`` the pixel centres sample image coordinates shifted by it (x right, y down),
        as :meth:`primary_rays` does.
        """
        f = 1.0 / np.tan(np.radians(self.fov if frame is None else self.fov_at(frame)) / 2.0)
        aspect = width / height
        n, fa = self.near, self.far
        p = np.zeros((4, 4))
        p[0, 0] = f / aspect
        p[1, 1] = f
        p[2, 2] = (fa + n) / (n - fa)
        p[2, 3] = 2 * fa * n / (n - fa)
        p[3, 2] = -1.0
        p[0, 2] = 2.0 * jitter[0] / width
        p[1, 2] = -2.0 * jitter[1] / height
        return p

    def view_projection(self, frame: int, width: int, height: int, jitter=(0.0, 0.0)) -> np.ndarray:
        """World-to-clip matrix of ``frame``."""
        return self.projection_matrix(width, height, jitter, frame) @ self.view_matrix(frame)

    def project(self, points: np.ndarray, frame: int, width: int, height: int, jitter=(0.0, 0.0)) -> np.ndarray:
        """Image coordinates (..., 2) of world ``points`` (..., 3) as seen in ``frame``.

        Uses the convention of :mod:`harness.buffers`: pixel (i, j) is centred on ``(x, y) = (j, i)``.
        Points behind the camera get NaN.
        """
        pts = np.asarray(points, np.float64)
        vp = self.view_projection(frame, width, height, jitter)
        clip = pts @ vp[:3, :3].T + vp[:3, 3]
        w = pts @ vp[3, :3] + vp[3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc_x = clip[..., 0] / w
            ndc_y = clip[..., 1] / w
        x = (ndc_x + 1.0) * 0.5 * width - 0.5
        y = (1.0 - ndc_y) * 0.5 * height - 0.5
        out = np.stack([x, y], axis=-1)
        out[w <= 0] = np.nan
        return out

    def primary_rays(self, frame: int, width: int, height: int, jitter=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions (H, W, 3) float64 through pixel centres (plus jitter).

        The ray of pixel (i, j) passes through image coordinates ``(j + jitter_x, i + jitter_y)``
        with pixel centres on integer coordinates, matching :meth:`view_projection`.
        """
        right, up, forward = self.basis(frame)
        t = np.tan(np.radians(self.fov_at(frame)) / 2.0)
        xs = (np.arange(width) + 0.5 + jitter[0]) / width * 2.0 - 1.0
        ys = 1.0 - (np.arange(height) + 0.5 + jitter[1]) / height * 2.0
        sx = xs[None, :] * t * (width / height)
        sy = ys[:, None] * t
        d = forward[None, None, :] + sx[..., None] * right[None, None, :] + sy[..., None] * up[None, None, :]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(self.eye(frame), d.shape).copy()
        return o, d


@dataclass
class SceneObject:
    """One mesh with its material(s) and rigid animation.

    Attributes
    ----------
    name : str
    mesh : pyvista.PolyData
        Triangles (or polygons, triangulated on use). Optional point data ``uv`` (n, 2) and
        ``normal`` (n, 3); optional cell data ``material`` (int32 indices into
        :attr:`Scene.materials`).
    material : int
        Material index for cells without ``material`` data.
    transforms : ndarray (F, 4, 4) or None
        Object-to-world matrix per frame (the last row repeats past the end); None = identity.
    """

    name: str
    mesh: Any
    material: int = 0
    transforms: np.ndarray | None = None

    def transform(self, frame: int) -> np.ndarray:
        if self.transforms is None:
            return np.eye(4)
        t = np.asarray(self.transforms, np.float64)
        if t.ndim == 2:
            return t
        return t[min(frame, len(t) - 1)]


@dataclass
class TriangleSoup:
    """A scene flattened to arrays for a renderer, for one frame (world space).

    Attributes
    ----------
    vertices : ndarray (T, 3, 3) float32
    normals : ndarray (T, 3, 3) float32
        Per-corner shading normals (face normal where the mesh has none).
    uvs : ndarray (T, 3, 2) float32
        Per-corner texture coordinates (zeros where the mesh has none).
    material : ndarray (T,) int32
    object_id : ndarray (T,) int32
        Index of the :class:`SceneObject` each triangle came from.
    """

    vertices: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    material: np.ndarray
    object_id: np.ndarray


#: what a scene can be
SCENE_KINDS = ("mesh", "procedural", "captured")


@dataclass
class Scene:
    """Everything a renderer needs for a sequence of frames.

    Attributes
    ----------
    name : str
    kind : {"mesh", "procedural", "captured"}
    frame_count : int
    resolution : (int, int)
        Default (width, height).
    tags : frozenset of str
    objects, materials : list
        Meshes and the materials they index (``mesh`` scenes).
    sun : Sun or None
    environment : Environment or None
    camera : CameraPath or None
    params : dict
        JSON-able parameters of a procedural scene (pattern name, noise level, motion ...).
    max_depth : int
        Path length limit suggested for this scene.
    source : str
        Where the scene came from (plugin name or folder), for reports.
    channels : frozenset of str, optional
        The channels this scene can give, where it limits what its renderer makes (a capture
        holds only some AOVs); None means whatever the renderer provides.
    """

    name: str
    kind: str = "mesh"
    frame_count: int = 1
    resolution: tuple = (256, 256)
    tags: frozenset = frozenset()
    objects: list = field(default_factory=list)
    materials: list = field(default_factory=list)
    sun: Sun | None = None
    environment: Environment | None = None
    camera: CameraPath | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    max_depth: int = 5
    source: str = ""
    channels: frozenset | None = None

    def __post_init__(self):
        if self.kind not in SCENE_KINDS:
            raise ValueError(f"scene {self.name!r}: kind must be one of {SCENE_KINDS}, got {self.kind!r}")
        if self.channels is not None:
            self.channels = frozenset(self.channels)
        self.tags = frozenset(self.tags)
        self.resolution = tuple(int(v) for v in self.resolution)
        self._hash: str | None = None

    def content_hash(self) -> str:
        """A stable SHA-256 over every input that affects an image (geometry, textures included)."""
        if self._hash is None:
            h = hashlib.sha256()
            header = {
                "name": self.name,
                "kind": self.kind,
                "frame_count": self.frame_count,
                "params": _jsonable(self.params),
                "max_depth": self.max_depth,
                "materials": [dataclasses.asdict(dataclasses.replace(m, texture=None)) for m in self.materials],
                "sun": dataclasses.asdict(self.sun) if self.sun else None,
                "environment": dataclasses.asdict(dataclasses.replace(self.environment, image=None))
                if self.environment
                else None,
            }
            h.update(json.dumps(header, sort_keys=True, default=str).encode())
            for m in self.materials:
                _hash_image(h, m.texture)
            if self.environment is not None:
                _hash_image(h, self.environment.image)
            if self.camera is not None:
                for a in (self.camera.positions, self.camera.targets):
                    h.update(np.ascontiguousarray(a, np.float64).tobytes())
                h.update(json.dumps([self.camera.up, self.camera.fov, self.camera.near, self.camera.far]).encode())
                for name in ("ups", "fovs"):  # animated roll and zoom (absent from static cameras' hashes)
                    if getattr(self.camera, name) is not None:
                        h.update(name.encode())
                        h.update(np.ascontiguousarray(getattr(self.camera, name), np.float64).tobytes())
            for obj in self.objects:
                h.update(obj.name.encode())
                h.update(str(obj.material).encode())
                mesh = obj.mesh
                for arr in (mesh.points, getattr(mesh, "faces", np.empty(0))):
                    h.update(np.ascontiguousarray(arr).tobytes())
                for key in sorted(mesh.point_data.keys()):
                    h.update(key.encode())
                    h.update(np.ascontiguousarray(mesh.point_data[key]).tobytes())
                for key in sorted(mesh.cell_data.keys()):
                    h.update(key.encode())
                    h.update(np.ascontiguousarray(mesh.cell_data[key]).tobytes())
                if obj.transforms is not None:
                    h.update(np.ascontiguousarray(obj.transforms, np.float64).tobytes())
            self._hash = h.hexdigest()
        return self._hash

    def triangles(self, frame: int = 0) -> TriangleSoup:
        """Flatten every object to world-space triangles for ``frame``."""
        verts, norms, uvs, mats, ids = [], [], [], [], []
        for oid, obj in enumerate(self.objects):
            mesh = obj.mesh
            if not mesh.is_all_triangles:
                mesh = mesh.triangulate()
            faces = np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]
            m = obj.transform(frame)
            pts = np.asarray(mesh.points, np.float64) @ m[:3, :3].T + m[:3, 3]
            tri = pts[faces]
            if "normal" in mesh.point_data:
                nrm_obj = np.asarray(mesh.point_data["normal"], np.float64)
                normal_matrix = np.linalg.inv(m[:3, :3]).T
                nrm = nrm_obj @ normal_matrix.T
                nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
                tri_n = nrm[faces]
            else:
                fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
                fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
                tri_n = np.repeat(fn[:, None, :], 3, axis=1)
            if "uv" in mesh.point_data:
                tri_uv = np.asarray(mesh.point_data["uv"], np.float64)[faces]
            else:
                tri_uv = np.zeros((len(faces), 3, 2))
            if "material" in mesh.cell_data:
                mat = np.asarray(mesh.cell_data["material"], np.int32)
            else:
                mat = np.full(len(faces), obj.material, np.int32)
            verts.append(tri)
            norms.append(tri_n)
            uvs.append(tri_uv)
            mats.append(mat)
            ids.append(np.full(len(faces), oid, np.int32))
        if not verts:
            empty = np.zeros((0, 3, 3), np.float32)
            return TriangleSoup(
                empty, empty.copy(), np.zeros((0, 3, 2), np.float32), np.zeros(0, np.int32), np.zeros(0, np.int32)
            )
        return TriangleSoup(
            np.concatenate(verts).astype(np.float32),
            np.concatenate(norms).astype(np.float32),
            np.concatenate(uvs).astype(np.float32),
            np.concatenate(mats),
            np.concatenate(ids),
        )

    def motion(self, position: np.ndarray, object_id: np.ndarray, frame: int, width: int, height: int) -> np.ndarray:
        """Motion vectors (H, W, 2) float32 for first hits of ``frame`` (see :mod:`harness.buffers`).

        Parameters
        ----------
        position : ndarray (H, W, 3)
            World position of each pixel's first hit.
        object_id : ndarray (H, W) int
            Index into :attr:`objects`, -1 for background (whose motion comes from the camera
            rotation alone: the direction is treated as infinitely far away).
        frame : int
        width, height : int

        Returns
        -------
        ndarray (H, W, 2) float32
            Offset to the pixel's position in frame ``frame - 1`` (zero in frame 0).
        """
        h, w = object_id.shape
        if frame == 0 or self.camera is None:
            return np.zeros((h, w, 2), np.float32)
        prev_pts = np.asarray(position, np.float64).copy()
        for oid, obj in enumerate(self.objects):
            if obj.transforms is None:
                continue
            mask = object_id == oid
            if not mask.any():
                continue
            rel = np.linalg.inv(obj.transform(frame))
            now_to_prev = obj.transform(frame - 1) @ rel
            p = prev_pts[mask]
            prev_pts[mask] = p @ now_to_prev[:3, :3].T + now_to_prev[:3, 3]
        xy_prev = self.camera.project(prev_pts, frame - 1, width, height)
        bg = object_id < 0
        if bg.any():
            _, d = self.camera.primary_rays(frame, width, height)
            far = self.camera.eye(frame - 1) + d[bg] * 1e6
            xy_prev[bg] = self.camera.project(far, frame - 1, width, height)
        jj, ii = np.meshgrid(np.arange(w), np.arange(h))
        mv = np.stack([xy_prev[..., 0] - jj, xy_prev[..., 1] - ii], axis=-1)
        return np.nan_to_num(mv, nan=0.0).astype(np.float32)


def _jsonable(value):
    return json.loads(json.dumps(value, sort_keys=True, default=str))


def _hash_image(h, image) -> None:
    if image is None:
        h.update(b"none")
    elif isinstance(image, np.ndarray):
        h.update(np.ascontiguousarray(image).tobytes())
    else:
        h.update(Path(image).read_bytes())
