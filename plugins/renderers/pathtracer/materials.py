"""Scene materials compiled to the flat node tables the kernels read.

Every material is a small tree of *nodes*: leaves are BSDFs (the kinds of :mod:`.bsdf`), inner
nodes are Mitsuba's wrappers (``twosided``, ``mask``, ``blendbsdf``, ``bumpmap``). A material of
the harness kinds becomes ``twosided(leaf)`` (``dielectric``: the leaf alone), which is what those
kinds always meant; a material with a Mitsuba description (``Scene.params["bsdfs"]``, written by
the Mitsuba scene plugin) becomes its tree with Mitsuba's parameters and defaults.

Tables
------
node_kind : (N,) int32
node_f : (N, NF) float64, columns named by the ``F_*`` constants of :mod:`.bsdf`
node_i : (N, NI) int32: texture of slots A, B, S (-1: none), children, rough-transmittance table
tables : float64, the 64-entry tables of rough plastics (Mitsuba's ``external_transmittance``)
tex_data, tex_off, tex_w, tex_h, tex_uv : every texture, float32 RGB, with its uv scale and offset
    (``su, sv, ou, ov``, in the harness's uv convention)
mat_root : (M,) int32, mat_flags : (M,) int32 (``ONE_SIDED_EMISSION``, ``HAS_MASK``)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness import Material

from . import bsdf as B
from .textures import read_description_texture

ONE_SIDED_EMISSION, HAS_MASK = 1, 2
TRANSMITTANCE_RES = 64  # Mitsuba's MI_ROUGH_TRANSMITTANCE_RES
_LEGACY = {"diffuse": B.DIFFUSE, "conductor": B.CONDUCTOR, "plastic": B.PLASTIC, "dielectric": B.DIELECTRIC,
           "mirror": B.MIRROR}


@dataclass
class MaterialTables:
    """The compiled materials (see the module docstring)."""

    mat_root: np.ndarray
    mat_flags: np.ndarray
    mat_emit: np.ndarray
    node_kind: np.ndarray
    node_f: np.ndarray
    node_i: np.ndarray
    tables: np.ndarray
    tex_data: np.ndarray
    tex_off: np.ndarray
    tex_w: np.ndarray
    tex_h: np.ndarray
    tex_uv: np.ndarray
    gbuffer_albedo: np.ndarray
    gbuffer_tex: np.ndarray

    def arrays(self) -> tuple:
        """The tuple the kernels take (``mats``)."""
        return (self.mat_root, self.mat_flags, self.mat_emit, self.node_kind, self.node_f, self.node_i, self.tables,
                self.tex_data, self.tex_off, self.tex_w, self.tex_h, self.tex_uv)


class _Builder:
    def __init__(self):
        self.kind: list[int] = []
        self.f: list[np.ndarray] = []
        self.i: list[np.ndarray] = []
        self.tables: list[np.ndarray] = []
        self._table_index: dict = {}
        self.images: list[np.ndarray] = []
        self._image_index: dict = {}
        self.textures: list[tuple[int, tuple]] = []  # (image, uv transform)
        self._texture_index: dict = {}
        self.has_mask = False

    # -- nodes ---------------------------------------------------------------------------------
    def node(self, kind: int) -> int:
        self.kind.append(kind)
        self.f.append(np.zeros(B.NF))
        row = np.full(B.NI, -1, np.int32)
        self.i.append(row)
        return len(self.kind) - 1

    def image(self, key, make) -> int:
        if key not in self._image_index:
            self._image_index[key] = len(self.images)
            self.images.append(np.ascontiguousarray(make(), np.float32))
        return self._image_index[key]

    def texture(self, image: int, uv=(1.0, 1.0, 0.0, 0.0)) -> int:
        key = (image, tuple(float(v) for v in uv))
        if key not in self._texture_index:
            self._texture_index[key] = len(self.textures)
            self.textures.append(key)
        return self._texture_index[key]

    def colour(self, n: int, slot: int, column: int, value) -> float:
        """Set colour slot ``slot`` of node ``n`` from a description value; returns its mean."""
        if isinstance(value, dict):
            img = self.image(("file", value["file"], bool(value["raw"])),
                             lambda: read_description_texture(value["file"], raw=bool(value["raw"])))
            self.i[n][slot] = self.texture(img, value.get("uv", (1.0, 1.0, 0.0, 0.0)))
            scale = float(value.get("scale", 1.0))
            self.f[n][column:column + 3] = scale
            return scale * float(self.images[img].mean())
        rgb = np.broadcast_to(np.asarray(value, float), 3)
        self.f[n][column:column + 3] = rgb
        return float(rgb.mean())

    def scalar(self, n: int, value) -> None:
        """Set the scalar slot (opacity, blend weight) of node ``n``."""
        if isinstance(value, dict):
            self.colour(n, B.I_TEX_S, B.F_S, value)
        else:
            self.f[n][B.F_S:B.F_S + 3] = float(np.mean(np.asarray(value, float)))

    def table(self, key, make) -> int:
        if key not in self._table_index:
            self._table_index[key] = sum(len(t) for t in self.tables)
            self.tables.append(np.asarray(make(), np.float64))
        return self._table_index[key]

    # -- materials -----------------------------------------------------------------------------
    def legacy(self, mat: Material, texture: int) -> int:
        kind = _LEGACY[mat.kind]
        leaf = self.node(kind)
        f32 = np.float32  # the values these kinds were always rendered with
        self.f[leaf][B.F_A:B.F_A + 3] = np.asarray(mat.albedo, f32)
        self.i[leaf][B.I_TEX_A] = texture
        self.f[leaf][B.F_B:B.F_B + 3] = np.asarray(mat.specular, f32)
        if kind == B.DIELECTRIC:
            self.f[leaf][B.F_A:B.F_B + 3] = 1.0
        self.f[leaf][B.F_AU] = self.f[leaf][B.F_AV] = f32(mat.roughness)
        self.f[leaf][B.F_ETA] = f32(mat.ior)
        if kind == B.DIELECTRIC:
            return leaf
        root = self.node(B.TWOSIDED)
        self.i[root][B.I_CHILD0] = self.i[root][B.I_CHILD1] = leaf
        return root

    def describe(self, d: dict) -> int:
        kind = d["type"]
        if kind == "twosided":
            n = self.node(B.TWOSIDED)
            children = [self.describe(c) for c in d["bsdfs"]]
            self.i[n][B.I_CHILD0] = children[0]
            self.i[n][B.I_CHILD1] = children[-1]
            return n
        if kind in ("mask", "bumpmap"):
            n = self.node(B.MASK if kind == "mask" else B.BUMP)
            if kind == "mask":
                self.has_mask = True
                self.scalar(n, d["opacity"])
            else:  # the height texture in slot S, its luminance read; the gradient multiplier in F_AU
                self.colour(n, B.I_TEX_S, B.F_S, d["texture"])
                self.f[n][B.F_AU] = float(d["scale"]) * self.f[n][B.F_S]
            self.i[n][B.I_CHILD0] = self.describe(d["bsdf"])
            return n
        if kind == "blendbsdf":
            n = self.node(B.BLEND)
            self.scalar(n, d["weight"])
            self.i[n][B.I_CHILD0] = self.describe(d["bsdfs"][0])
            self.i[n][B.I_CHILD1] = self.describe(d["bsdfs"][1])
            return n
        if kind in ("diffuse", "roughdiffuse"):
            n = self.node(B.DIFFUSE if kind == "diffuse" else B.ROUGHDIFFUSE)
            self.colour(n, B.I_TEX_A, B.F_A, d["reflectance"])
            self.f[n][B.F_AU] = d.get("alpha", 0.0)
            return n
        if kind in ("plastic", "roughplastic"):
            n = self.node(B.MI_PLASTIC if kind == "plastic" else B.MI_ROUGHPLASTIC)
            d_mean = self.colour(n, B.I_TEX_A, B.F_A, d["diffuse_reflectance"])
            s_mean = self.colour(n, B.I_TEX_B, B.F_B, d["specular_reflectance"])
            eta = d["int_ior"] / d["ext_ior"]
            f = self.f[n]
            f[B.F_ETA] = eta
            f[B.F_NONLINEAR] = 1.0 if d["nonlinear"] else 0.0
            f[B.F_SSW] = s_mean / max(d_mean + s_mean, 1e-12)
            if kind == "plastic":
                f[B.F_RI] = fresnel_diffuse_reflectance(1.0 / eta)
            else:
                beckmann = d["distribution"] == "beckmann"
                alpha = float(d["alpha"])
                f[B.F_AU] = f[B.F_AV] = alpha
                f[B.F_DIST] = 1.0 if beckmann else 0.0
                mu = np.maximum(np.linspace(0.0, 1.0, TRANSMITTANCE_RES), 1e-6)
                self.i[n][B.I_TABLE] = self.table(("T", alpha, eta, beckmann),
                                                  lambda: rough_interface(mu, alpha, eta, beckmann)[1])
                f[B.F_RI] = 2.0 * float(np.mean(rough_interface(mu, alpha, 1.0 / eta, beckmann)[0] * mu))
            return n
        if kind in ("conductor", "roughconductor"):
            n = self.node(B.MI_CONDUCTOR if kind == "conductor" else B.MI_ROUGHCONDUCTOR)
            self.colour(n, B.I_TEX_B, B.F_B, d["specular_reflectance"])
            ext = float(d.get("ext_eta", 1.0))
            for column, name in ((B.F_ETA, "eta"), (B.F_K, "k")):
                value = d[name]
                value = np.mean(np.asarray(value.get("mean", 1.0))) if isinstance(value, dict) else value
                self.f[n][column:column + 3] = np.broadcast_to(np.asarray(value, float), 3) / ext
            if kind == "roughconductor":
                self._microfacet(n, d)
            return n
        if kind in ("dielectric", "roughdielectric", "thindielectric"):
            code = {"dielectric": B.DIELECTRIC, "roughdielectric": B.MI_ROUGHDIELECTRIC,
                    "thindielectric": B.MI_THINDIELECTRIC}[kind]
            n = self.node(code)
            self.colour(n, B.I_TEX_A, B.F_A, d["specular_reflectance"])
            self.colour(n, B.I_TEX_B, B.F_B, d["specular_transmittance"])
            self.f[n][B.F_ETA] = d["int_ior"] / d["ext_ior"]
            if kind == "roughdielectric":
                self._microfacet(n, d)
            return n
        raise ValueError(f"renderer 'pathtracer': unknown bsdf description type {kind!r}")

    def _microfacet(self, n: int, d: dict) -> None:
        self.f[n][B.F_AU] = d["alpha_u"]
        self.f[n][B.F_AV] = d["alpha_v"]
        self.f[n][B.F_DIST] = 1.0 if d["distribution"] == "beckmann" else 0.0


def compile_materials(materials: list[Material], descriptions) -> MaterialTables:
    """Compile a scene's materials (and their Mitsuba descriptions, when given) to node tables.

    Parameters
    ----------
    materials : list of harness.Material
    descriptions : list of dict or None, or None
        ``Scene.params["bsdfs"]``: per material ``{"bsdf": description, "one_sided_emission": bool}``.
    """
    b = _Builder()
    roots, flags = [], []
    gbuf, gtex = [], []
    for index, mat in enumerate(materials):
        entry = descriptions[index] if descriptions is not None and index < len(descriptions) else None
        gbuf.append(mat.specular if mat.kind in ("conductor", "mirror") else (1.0, 1.0, 1.0)
                    if mat.kind == "dielectric" else mat.albedo)
        img = mat.texture_array()
        if img is None:
            gtex.append(-1)
        else:
            image = b.image(("material", index), lambda img=img: np.clip(np.nan_to_num(img, nan=0.0), 0.0, None))
            gtex.append(b.texture(image))
        b.has_mask = False
        if entry is not None and entry.get("bsdf") is not None:
            roots.append(b.describe(entry["bsdf"]))
            flag = ONE_SIDED_EMISSION if entry.get("one_sided_emission") else 0
        else:
            roots.append(b.legacy(mat, gtex[-1] if mat.kind != "dielectric" else -1))
            flag = 0
        flags.append(flag | (HAS_MASK if b.has_mask else 0))
    m = len(materials)
    images = b.images or [np.zeros((1, 1, 3), np.float32)]
    offsets = np.cumsum([0] + [img.size for img in images[:-1]]).astype(np.int64)
    tex_off = np.array([offsets[img] for img, _ in b.textures] or [0], np.int64)
    tex_w = np.array([images[img].shape[1] for img, _ in b.textures] or [1], np.int32)
    tex_h = np.array([images[img].shape[0] for img, _ in b.textures] or [1], np.int32)
    # Mitsuba's v' = sv v + ov on its v = 1 - harness v is, in the harness's v: sv v + (1 - sv - ov)
    tex_uv = np.array([(su, sv, ou, 1.0 - sv - ov) for _, (su, sv, ou, ov) in b.textures] or [(1.0, 1.0, 0.0, 0.0)],
                      np.float64).reshape(-1, 4)
    return MaterialTables(
        mat_root=np.array(roots, np.int32),
        mat_flags=np.array(flags, np.int32),
        mat_emit=np.array([x.emission for x in materials], np.float32).reshape(m, 3),
        node_kind=np.array(b.kind, np.int32),
        node_f=np.ascontiguousarray(np.array(b.f, np.float64).reshape(-1, B.NF)),
        node_i=np.ascontiguousarray(np.array(b.i, np.int32).reshape(-1, B.NI)),
        tables=np.concatenate(b.tables) if b.tables else np.zeros(1),
        tex_data=np.concatenate([img.ravel() for img in images]).astype(np.float32),
        tex_off=tex_off, tex_w=tex_w, tex_h=tex_h, tex_uv=tex_uv,
        gbuffer_albedo=np.array(gbuf, np.float32).reshape(m, 3),
        gbuffer_tex=np.array(gtex, np.int32),
    )


def fresnel_diffuse_reflectance(eta: float) -> float:
    """Hemispherical average of the dielectric Fresnel reflectance, as Mitsuba approximates it:
    Egan and Hilgeman's fit for ``eta < 1``, d'Eon and Irving's (2011) polynomial in ``1 / eta`` otherwise."""
    if eta < 1.0:
        return -1.4399 * eta * eta + 0.7099 * eta + 0.6681 + 0.0636 / eta
    x = 1.0 / eta
    return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554 + x * -1.36881))))


def _fresnel(c: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """Dielectric Fresnel reflectance and cos(theta_t) (>= 0) for ``c = cos(theta_i) >= 0``."""
    sin_t2 = (1.0 - c * c) / (eta * eta)
    cos_t = np.sqrt(np.maximum(1.0 - sin_t2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (c - eta * cos_t) / (c + eta * cos_t)
        rp = (eta * c - cos_t) / (eta * c + cos_t)
    f = np.where(sin_t2 >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))
    return np.nan_to_num(f, nan=1.0), cos_t


def rough_interface(mu: np.ndarray, alpha: float, eta: float, beckmann: bool,
                    n_theta: int = 192, n_phi: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """Directional reflectance and transmittance of a rough dielectric interface (isotropic).

    For a direction of cosine ``mu`` (z-up, x-z plane), the averages over visible microfacet
    normals ``m`` (density ``D(m) G1(wi, m) <wi, m> / mu``) of ``F(<wi, m>) G1(wr, m)`` and of
    ``(1 - F(<wi, m>)) G1(wt, m)`` (``wr``, ``wt``: the reflected and refracted directions, the latter
    counted only below the surface), with Mitsuba's separable Smith ``G1``: the quantities Mitsuba's
    ``eval_reflectance`` / ``eval_transmittance`` compute. Integrated here by Gauss-Legendre in
    ``s`` with ``tan(theta_m) = alpha tan(pi s / 2)`` and the trapezoidal rule in phi.

    Returns
    -------
    reflectance, transmittance : ndarray like ``mu``
    """
    s, ws = np.polynomial.legendre.leggauss(n_theta)
    s = 0.5 * (s + 1.0)
    ws = 0.5 * ws
    t = np.tan(0.5 * math.pi * s)
    theta = np.arctan(alpha * t)
    dtheta = ws * alpha * 0.5 * math.pi / np.cos(0.5 * math.pi * s) ** 2 / (1.0 + (alpha * t) ** 2)
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * math.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    weight = (dtheta[:, None] * np.sin(th)) * (2.0 * math.pi / n_phi)
    m = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    cos_m = m[..., 2]
    tan2 = np.tan(th) ** 2
    if beckmann:
        d = np.exp(-tan2 / alpha**2) / (math.pi * alpha**2 * cos_m**4)
    else:
        d = 1.0 / (math.pi * alpha**2 * cos_m**4 * (1.0 + tan2 / alpha**2) ** 2)

    def g1(v, mm):
        vz = v[..., 2]
        xy = alpha**2 * (v[..., 0] ** 2 + v[..., 1] ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            ta2 = xy / (vz * vz)
            if beckmann:
                a = 1.0 / np.sqrt(ta2)
                g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
            else:
                g = 2.0 / (1.0 + np.sqrt(1.0 + ta2))
        g = np.where(xy == 0.0, 1.0, g)
        return np.where(np.sum(v * mm, -1) * vz <= 0.0, 0.0, np.nan_to_num(g))

    refl = np.zeros(len(mu))
    trans = np.zeros(len(mu))
    for j, c in enumerate(np.asarray(mu, float)):
        wi = np.array([math.sqrt(max(1.0 - c * c, 0.0)), 0.0, c])
        dot = m @ wi
        vis = np.maximum(dot, 0.0) * d * g1(np.broadcast_to(wi, m.shape), m) / c * weight
        f, cos_t = _fresnel(np.abs(dot), eta)
        wr = 2.0 * dot[..., None] * m - wi
        wt = -wi / eta + (dot / eta - cos_t)[..., None] * m
        refl[j] = np.sum(vis * f * np.where(wr[..., 2] > 0.0, g1(wr, m), 0.0))
        trans[j] = np.sum(vis * (1.0 - f) * np.where(wt[..., 2] < 0.0, g1(wt, m), 0.0))
    return refl, trans
