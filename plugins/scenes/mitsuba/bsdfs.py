"""Mitsuba BSDFs as renderer-neutral descriptions, plus the :class:`harness.Material` closest to each.

A Mitsuba ``<bsdf>`` element becomes two things:

- a *description*: a JSON-able tree of plain dicts holding the BSDF exactly as the file states it,
  with Mitsuba 3's parameter names and defaults (``{"type": "roughplastic", "alpha": 0.1,
  "distribution": "ggx", "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": True,
  "diffuse_reflectance": ..., "specular_reflectance": ...}``; wrappers hold ``"bsdf"`` or
  ``"bsdfs"``). A colour or scalar parameter is a number, an ``[r, g, b]`` list, or a texture
  ``{"file": path, "raw": bool, "digest": sha256 of the file, "uv": [su, sv, ou, ov]}`` (plus
  ``"scale": s`` where a ``scale`` texture wraps the bitmap). The
  loader stores the descriptions in ``Scene.params["bsdfs"]`` (one per material, ``None`` for
  none); a renderer that knows them (the path tracer) renders Mitsuba's semantics;
- a :class:`harness.Material` of one of the harness kinds, for renderers that only know those
  (the raster G-buffer: albedo and texture).

Only what cannot be described is warned about (an unknown BSDF or texture type, a spectrum given
by wavelengths); the description itself is exact.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import Material

from .files import scene_file
from .xmlscene import color_value, find, get_bool, get_float, get_string, transform, warn

# Mitsuba 3's named indices of refraction (its ``ior.h`` table)
NAMED_IOR = {"vacuum": 1.0, "helium": 1.000036, "hydrogen": 1.000132, "air": 1.000277, "carbon dioxide": 1.00045,
             "water": 1.3330, "acetone": 1.36, "ethanol": 1.361, "carbon tetrachloride": 1.461, "glycerol": 1.4729,
             "benzene": 1.501, "silicone oil": 1.52045, "bromine": 1.661, "water ice": 1.31,
             "fused quartz": 1.458, "pyrex": 1.470, "acrylic glass": 1.49, "polypropylene": 1.49, "bk7": 1.5046,
             "sodium chloride": 1.544, "amber": 1.55, "pet": 1.5750, "diamond": 2.419}
# Mitsuba 3's named conductors in its RGB variants: (eta, k) per channel, as ``scalar_rgb`` turns
# the measured spectra into sRGB
CONDUCTORS = {
    "a-c": ((2.94405, 2.22714, 1.96816), (0.88746, 0.7993, 0.81529)),
    "ag": ((0.15528, 0.11673, 0.13839), (4.82835, 3.12222, 2.1469)),
    "al": ((1.6575, 0.8804, 0.52124), (9.22381, 6.2695, 4.837)),
    "alas": ((3.6053, 3.23294, 2.21632), (0.00068, 0.0, 0.00751)),
    "alsb": ((0.0, 4.13937, 4.66925), (0.0, 0.09401, 1.30057)),
    "au": ((0.14304, 0.37531, 1.44205), (3.983, 2.38556, 1.60336)),
    "be": ((4.18501, 3.18503, 2.78406), (3.83547, 3.01012, 2.86899)),
    "cr": ((4.36967, 2.91651, 1.6549), (5.20655, 4.23131, 3.7547)),
    "csi": ((2.1449, 1.70232, 1.66243), (0.0, 0.0, 0.0)),
    "cu": ((0.20101, 0.92375, 1.10222), (3.91326, 2.45305, 2.14209)),
    "cu2o": ((3.55177, 2.94987, 2.75188), (0.11421, 0.1939, 0.60613)),
    "cuo": ((3.24754, 2.44781, 2.21022), (0.52109, 0.57003, 0.72218)),
    "d-c": ((2.70872, 2.31883, 2.2289), (0.0, 0.0, 0.0)),
    "hg": ((2.39894, 1.44003, 0.90957), (6.32759, 4.37192, 3.42176)),
    "hgte": ((4.77904, 3.2312, 2.6599), (1.63161, 1.58081, 1.72929)),
    "ir": ((3.0863, 2.08219, 1.61791), (5.59215, 4.06709, 3.26731)),
    "k": ((0.06404, 0.04641, 0.03818), (2.1042, 1.34894, 0.91313)),
    "li": ((0.26579, 0.19562, 0.22095), (3.54015, 2.31112, 1.66861)),
    "mgo": ((2.08958, 1.65072, 1.59488), (0.0, 0.0, 0.0)),
    "mo": ((4.48397, 3.52513, 2.77631), (4.11144, 3.42083, 3.15061)),
    "na_palik": ((0.06027, 0.05614, 0.06199), (3.17927, 2.11249, 1.57904)),
    "nb_palik": ((3.42007, 2.79009, 2.39563), (3.44139, 2.73767, 2.57975)),
    "ni_palik": ((2.3673, 1.66337, 1.46708), (4.49881, 3.05015, 2.34544)),
    "rh": ((2.58579, 1.86022, 1.55426), (6.78226, 4.70299, 3.97607)),
    "se": ((4.05831, 2.84294, 2.82085), (0.75405, 0.63844, 0.52181)),
    "sic": ((3.17234, 2.52597, 2.47937), (0.0, 0.0, 1e-05)),
    "snte": ((4.52425, 1.98164, 1.28159), (0.0, 0.0, 0.0)),
    "ta": ((2.06272, 2.39294, 2.62793), (2.40836, 1.74149, 1.94703)),
    "te": ((7.39023, 4.4821, 2.63711), (3.25602, 3.52706, 3.29205)),
    "thf4": ((1.83071, 1.44223, 1.38765), (0.0, 0.0, 0.0)),
    "tic": ((3.70053, 2.83742, 2.58229), (3.26564, 2.35159, 2.17279)),
    "tin": ((1.64845, 1.15052, 1.37982), (3.36833, 1.9435, 1.10207)),
    "tio2": ((3.45661, 2.80174, 2.90517), (0.00011, 0.0, 0.00065)),
    "vc": ((3.65757, 2.75274, 2.53267), (3.0683, 2.19869, 1.96319)),
    "v_palik": ((4.27758, 3.51295, 2.76107), (3.4913, 2.88945, 3.11152)),
    "vn": ((2.8656, 2.11919, 1.94009), (3.03224, 2.05612, 1.61631)),
    "w": ((4.37082, 3.30025, 2.99841), (3.50064, 2.60487, 2.27323)),
}
WRAPPERS = ("twosided", "mask", "bumpmap", "blendbsdf")
LEAVES = ("diffuse", "roughdiffuse", "plastic", "roughplastic", "conductor", "roughconductor", "dielectric",
          "roughdielectric", "thindielectric")


class BsdfContext:
    """What BSDF conversion needs: the scene folder, every element with an ``id`` anywhere in the
    file (Mitsuba resolves ``<ref>`` to any of them), and the descriptions made so far."""

    def __init__(self, folder: Path, root: ET.Element):
        self.folder = folder
        self.ids = {e.get("id"): e for e in root.iter() if e.get("id") and e.tag in ("bsdf", "texture")}
        self.descriptions: dict[str, dict] = {}
        self._digests: dict[Path, str] = {}

    def digest(self, path: Path) -> str:
        """SHA-256 of a texture file (so a scene's hash changes with its textures), or "missing"."""
        if path not in self._digests:
            self._digests[path] = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "missing"
        return self._digests[path]


def _ior(node: ET.Element, name: str, default: float) -> float:
    prop = find(node, name)
    if prop is None:
        return default
    value = prop.get("value", "")
    try:
        return float(value)
    except ValueError:
        if value.lower() in NAMED_IOR:
            return NAMED_IOR[value.lower()]
        warn(f"unknown index of refraction {value!r}; using {default}")
        return default


def _resolve(prop: ET.Element, ctx: BsdfContext) -> ET.Element:
    if prop.tag == "ref" and prop.get("id") in ctx.ids:
        return ctx.ids[prop.get("id")]
    return prop


def spectrum(node: ET.Element, name: str, ctx: BsdfContext, default):
    """The colour or texture parameter ``name`` of ``node`` (see the module docstring), or ``default``."""
    prop = find(node, name)
    if prop is None:
        return default
    prop = _resolve(prop, ctx)
    if prop.tag == "texture":
        return texture(prop, ctx, default)
    value = color_value(prop)
    if value is None:
        warn(f"unsupported parameter <{prop.tag}> {name!r}; using {default}")
        return default
    return [float(v) for v in value]


def texture(node: ET.Element, ctx: BsdfContext, default):
    """A ``bitmap`` texture as a description; other texture types are approximated (warned)."""
    kind = node.get("type")
    if kind == "bitmap":
        path = scene_file(node, ctx.folder)
        su = get_float(node, "uscale", 1.0)
        sv = get_float(node, "vscale", 1.0)
        ou = get_float(node, "uoffset", 0.0)
        ov = get_float(node, "voffset", 0.0)
        if find(node, "toUV") is not None:
            m = transform(find(node, "toUV"))
            su, sv, ou, ov = float(m[0, 0]), float(m[1, 1]), float(m[0, 3]), float(m[1, 3])
            if abs(m[0, 1]) > 1e-9 or abs(m[1, 0]) > 1e-9:
                warn(f"bitmap {path.name}: to_uv rotation or shear dropped (scale and offset kept)")
        raw = get_bool(node, "raw", False)
        if find(node, "gamma") is not None:
            raw = abs(get_float(node, "gamma", 0.0) - 1.0) < 1e-6 or raw
        return {"file": str(path), "raw": raw, "digest": ctx.digest(path), "uv": [su, sv, ou, ov]}
    if kind == "checkerboard":
        a = find(node, "color0")
        b = find(node, "color1")
        a = color_value(a) if a is not None else (0.4,) * 3
        b = color_value(b) if b is not None else (0.2,) * 3
        warn("checkerboard texture approximated by the mean of its two colours")
        return [float(v) for v in (np.asarray(a) + np.asarray(b)) / 2]
    if kind == "scale":
        inner = next((_resolve(c, ctx) for c in node if _resolve(c, ctx).tag == "texture"), None)
        value = texture(inner, ctx, default) if inner is not None else default
        factor = get_float(node, "scale", 1.0)
        if isinstance(value, dict):
            return {**value, "scale": factor * value.get("scale", 1.0)}
        return value if value is None else [float(v) * factor for v in np.broadcast_to(np.asarray(value, float), 3)]
    warn(f"texture type {kind!r} is not supported; using {default}")
    return default


def _microfacet(node: ET.Element, desc: dict) -> dict:
    desc["distribution"] = (get_string(node, "distribution", "beckmann") or "beckmann").lower()
    if desc["distribution"] not in ("ggx", "beckmann"):
        warn(f"microfacet distribution {desc['distribution']!r} is not supported; using beckmann")
        desc["distribution"] = "beckmann"
    alpha = get_float(node, "alpha", 0.1)
    desc["alpha_u"] = get_float(node, "alphaU", alpha)
    desc["alpha_v"] = get_float(node, "alphaV", alpha)
    return desc


def describe(node: ET.Element, ctx: BsdfContext) -> dict:
    """The description of the ``<bsdf>`` element ``node`` (nested ids registered on the way)."""
    node = _resolve(node, ctx)
    ident = node.get("id")
    if ident and ident in ctx.descriptions:
        return ctx.descriptions[ident]
    desc = _describe(node, ctx)
    if ident:
        ctx.descriptions[ident] = desc
    return desc


def _children(node: ET.Element, ctx: BsdfContext) -> list[dict]:
    out = []
    for child in node:
        if child.tag == "bsdf" or (child.tag == "ref" and ctx.ids.get(child.get("id")) is not None
                                   and ctx.ids[child.get("id")].tag == "bsdf"):
            out.append(describe(child, ctx))
    return out


def _describe(node: ET.Element, ctx: BsdfContext) -> dict:
    kind = node.get("type")
    if kind in WRAPPERS:
        children = _children(node, ctx)
        if not children:
            warn(f"bsdf {kind!r} has no nested bsdf; using diffuse grey")
            return {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}
        if kind == "twosided":
            return {"type": "twosided", "bsdfs": children[:2]}
        if kind == "mask":
            return {"type": "mask", "opacity": spectrum(node, "opacity", ctx, 0.5), "bsdf": children[0]}
        if kind == "blendbsdf":
            if len(children) < 2:
                warn("blendbsdf with fewer than two nested bsdfs; using the first")
                return children[0]
            return {"type": "blendbsdf", "weight": spectrum(node, "weight", ctx, 0.5), "bsdfs": children[:2]}
        height = None
        for child in node:
            child = _resolve(child, ctx)
            if child.tag == "texture":
                height = texture(child, ctx, None)
        if not isinstance(height, dict):
            warn("bumpmap without a bitmap height texture: the nested bsdf is rendered with unperturbed normals")
            return children[0]
        return {"type": "bumpmap", "texture": height, "scale": get_float(node, "scale", 1.0), "bsdf": children[0]}
    if kind == "diffuse":
        return {"type": "diffuse", "reflectance": spectrum(node, "reflectance", ctx, 0.5)}
    if kind == "roughdiffuse":
        warn("roughdiffuse: rendered with Oren-Nayar's qualitative model (Mitsuba 0.6's fast approximation); "
             "Mitsuba 3 has no roughdiffuse to compare with")
        return {"type": "roughdiffuse", "reflectance": spectrum(node, "reflectance", ctx, 0.5),
                "alpha": get_float(node, "alpha", 0.2)}
    if kind in ("plastic", "roughplastic"):
        desc = {"type": kind, "diffuse_reflectance": spectrum(node, "diffuseReflectance", ctx, 0.5),
                "specular_reflectance": spectrum(node, "specularReflectance", ctx, 1.0),
                "int_ior": _ior(node, "intIOR", NAMED_IOR["polypropylene"]),
                "ext_ior": _ior(node, "extIOR", NAMED_IOR["air"]),
                "nonlinear": get_bool(node, "nonlinear", False)}
        if kind == "roughplastic":
            _microfacet(node, desc)
            if desc["alpha_u"] != desc["alpha_v"]:
                warn("roughplastic: anisotropic roughness is not supported by Mitsuba either; using alpha_u")
            desc["alpha"] = desc.pop("alpha_u")
            desc.pop("alpha_v")
        return desc
    if kind in ("conductor", "roughconductor"):
        material = (get_string(node, "material", "none") or "none").lower()
        if find(node, "eta") is not None or find(node, "k") is not None:
            eta = spectrum(node, "eta", ctx, 0.0)
            k = spectrum(node, "k", ctx, 1.0)
        elif material == "none":
            eta, k = 0.0, 1.0
        elif material in CONDUCTORS:
            eta, k = (list(v) for v in CONDUCTORS[material])
        else:
            warn(f"conductor material {material!r} is not in Mitsuba's table; using a perfect mirror")
            eta, k = 0.0, 1.0
        desc = {"type": kind, "eta": eta, "k": k, "ext_eta": _ior(node, "extEta", 1.0),
                "specular_reflectance": spectrum(node, "specularReflectance", ctx, 1.0)}
        if material == "none" and find(node, "eta") is None:
            desc["mirror"] = True
        return _microfacet(node, desc) if kind == "roughconductor" else desc
    if kind in ("dielectric", "roughdielectric", "thindielectric"):
        desc = {"type": kind, "int_ior": _ior(node, "intIOR", NAMED_IOR["bk7"]),
                "ext_ior": _ior(node, "extIOR", NAMED_IOR["air"]),
                "specular_reflectance": spectrum(node, "specularReflectance", ctx, 1.0),
                "specular_transmittance": spectrum(node, "specularTransmittance", ctx, 1.0)}
        return _microfacet(node, desc) if kind == "roughdielectric" else desc
    if kind == "phong":
        exponent = get_float(node, "exponent", 30.0)
        alpha = float(np.sqrt(2.0 / (exponent + 2.0)))
        warn(f"phong approximated by a roughplastic of Beckmann alpha sqrt(2 / (exponent + 2)) = {alpha:.3g} "
             "(Mitsuba 3 has no phong)")
        return {"type": "roughplastic", "diffuse_reflectance": spectrum(node, "diffuseReflectance", ctx, 0.5),
                "specular_reflectance": spectrum(node, "specularReflectance", ctx, 0.2), "int_ior": 1.49,
                "ext_ior": 1.000277, "nonlinear": False, "distribution": "beckmann", "alpha": alpha}
    warn(f"bsdf type {kind!r} is not supported; using diffuse grey")
    return {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}


def _mean(value) -> tuple:
    """(rgb, texture path) of a description parameter, for the harness material."""
    if isinstance(value, dict):
        return (1.0, 1.0, 1.0), value["file"]
    rgb = np.broadcast_to(np.asarray(value, float), 3)
    return tuple(float(v) for v in rgb), None


def _f0(eta: float) -> float:
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def material(desc: dict, name: str) -> Material:
    """The harness material closest to a description (what renderers without descriptions use)."""
    kind = desc["type"]
    if kind in ("twosided", "mask", "bumpmap"):
        return material(desc["bsdfs"][0] if kind == "twosided" else desc["bsdf"], name)
    if kind == "blendbsdf":
        return material(desc["bsdfs"][0], name)
    if kind in ("diffuse", "roughdiffuse"):
        albedo, tex = _mean(desc["reflectance"])
        return Material(name, albedo=albedo, texture=tex)
    if kind in ("plastic", "roughplastic"):
        albedo, tex = _mean(desc["diffuse_reflectance"])
        eta = desc["int_ior"] / desc["ext_ior"]
        return Material(name, kind="plastic", albedo=albedo, texture=tex, roughness=desc.get("alpha", 0.01),
                        specular=(_f0(eta),) * 3, ior=eta)
    if kind in ("conductor", "roughconductor"):
        eta = np.broadcast_to(np.asarray(desc["eta"] if not isinstance(desc["eta"], dict) else 1.0, float), 3)
        k = np.broadcast_to(np.asarray(desc["k"] if not isinstance(desc["k"], dict) else 1.0, float), 3)
        scale, _ = _mean(desc["specular_reflectance"])
        f0 = np.clip(((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2) * np.asarray(scale), 0.0, 1.0)
        f0 = tuple(float(v) for v in f0)
        if kind == "conductor":
            return Material(name, kind="mirror", specular=f0, albedo=f0, roughness=0.0)
        alpha = float(np.sqrt(desc["alpha_u"] * desc["alpha_v"]))
        return Material(name, kind="conductor", specular=f0, albedo=f0, roughness=alpha)
    eta = desc["int_ior"] / desc["ext_ior"]
    return Material(name, kind="dielectric", albedo=(1.0, 1.0, 1.0), ior=eta, roughness=0.0,
                    specular=(_f0(eta),) * 3)


def is_glossy(desc: dict) -> bool:
    """Whether a description has a specular or glossy lobe (for the scene's ``glossy`` tag)."""
    kind = desc["type"]
    if kind in ("twosided", "blendbsdf"):
        return any(is_glossy(d) for d in desc["bsdfs"])
    if kind in ("mask", "bumpmap"):
        return is_glossy(desc["bsdf"])
    if kind in ("diffuse", "roughdiffuse"):
        return False
    return kind != "roughplastic" or desc["alpha"] < 0.3


def has_texture(desc) -> bool:
    """Whether any parameter of a description is a texture."""
    if isinstance(desc, dict):
        return "file" in desc or any(has_texture(v) for v in desc.values())
    if isinstance(desc, list):
        return any(has_texture(v) for v in desc)
    return False


__all__ = ["BsdfContext", "CONDUCTORS", "NAMED_IOR", "describe", "has_texture", "is_glossy", "material", "spectrum"]
