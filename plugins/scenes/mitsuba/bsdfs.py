"""Mitsuba BSDFs mapped onto :class:`harness.Material` (a warning for every approximation)."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import Material

from .xmlscene import color_value, find, get_float, get_string, warn

# normal-incidence reflectance of Mitsuba's named conductors (approximate, linear RGB)
CONDUCTOR_F0 = {
    "ag": (0.97, 0.96, 0.91), "al": (0.91, 0.92, 0.92), "au": (1.0, 0.78, 0.34), "cu": (0.96, 0.64, 0.54),
    "cr": (0.55, 0.56, 0.55), "none": (1.0, 1.0, 1.0),
}
NAMED_IOR = {"vacuum": 1.0, "air": 1.000277, "water": 1.333, "bk7": 1.5046, "glass": 1.5, "polypropylene": 1.49,
             "acrylic glass": 1.49, "diamond": 2.419, "pet": 1.575}
WRAPPERS = ("twosided", "mask", "bumpmap", "normalmap", "coating", "roughcoating", "blendbsdf", "mixturebsdf")


class BsdfContext:
    """What BSDF conversion needs: the scene folder and the top-level named textures."""

    def __init__(self, folder: Path, textures: dict[str, ET.Element]):
        self.folder = folder
        self.textures = textures


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


def _reflectance(node: ET.Element, names: tuple[str, ...], ctx: BsdfContext, default):
    """(albedo, texture path or None) of the first of ``names`` present in ``node``."""
    for name in names:
        prop = find(node, name)
        if prop is None:
            continue
        if prop.tag == "ref":
            prop = ctx.textures.get(prop.get("id"), prop)
        if prop.tag == "texture":
            return _texture(prop, ctx)
        value = color_value(prop)
        if value is not None:
            return value, None
        warn(f"unsupported reflectance <{prop.tag}> in bsdf; using {default}")
    return default, None


def _texture(node: ET.Element, ctx: BsdfContext):
    kind = node.get("type")
    if kind == "bitmap":
        for attr in ("uscale", "vscale", "uoffset", "voffset"):
            if find(node, attr) is not None:
                warn(f"bitmap texture {attr} is ignored")
        return (1.0, 1.0, 1.0), str(ctx.folder / get_string(node, "filename"))
    if kind == "checkerboard":
        warn("checkerboard texture approximated by the mean of its two colours")
        a = color_value(find(node, "color0")) if find(node, "color0") is not None else (0.4,) * 3
        b = color_value(find(node, "color1")) if find(node, "color1") is not None else (0.2,) * 3
        return tuple((np.asarray(a) + np.asarray(b)) / 2), None
    warn(f"texture type {kind!r} is not supported; using grey 0.5")
    return (0.5, 0.5, 0.5), None


def _f0_from_ior(eta: float) -> float:
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def convert(node: ET.Element, name: str, ctx: BsdfContext) -> Material:
    """A :class:`harness.Material` approximating the ``<bsdf>`` element ``node``."""
    kind = node.get("type")
    if kind in WRAPPERS:
        inner = node.find("bsdf")
        if inner is None and node.find("ref") is not None:
            warn(f"bsdf {kind!r} wraps a reference, which is not resolved; using diffuse grey")
            return Material(name, albedo=(0.5, 0.5, 0.5))
        if kind != "twosided":
            warn(f"bsdf {kind!r} of {name!r} approximated by its (first) nested bsdf")
        if inner is None:
            return Material(name, albedo=(0.5, 0.5, 0.5))
        return convert(inner, name, ctx)
    if kind in ("diffuse", "roughdiffuse"):
        if kind == "roughdiffuse":
            warn(f"roughdiffuse {name!r} approximated by Lambertian diffuse")
        albedo, texture = _reflectance(node, ("reflectance",), ctx, (0.5, 0.5, 0.5))
        return Material(name, albedo=albedo, texture=texture)
    if kind in ("plastic", "roughplastic"):
        albedo, texture = _reflectance(node, ("diffuseReflectance", "reflectance"), ctx, (0.5, 0.5, 0.5))
        eta = _ior(node, "intIOR", 1.49) / _ior(node, "extIOR", 1.000277)
        alpha = get_float(node, "alpha", 0.1) if kind == "roughplastic" else 0.01
        if kind == "plastic":
            warn(f"smooth plastic {name!r} approximated by a GGX coat of alpha 0.01")
        spec = get_float(node, "specularReflectance", 1.0) if find(node, "specularReflectance") is not None and \
            find(node, "specularReflectance").tag == "float" else 1.0
        return Material(name, kind="plastic", albedo=albedo, texture=texture, roughness=alpha,
                        specular=(_f0_from_ior(eta) * spec,) * 3, ior=eta)
    if kind in ("conductor", "roughconductor"):
        material = (get_string(node, "material", "Cu") or "Cu").lower()
        if find(node, "eta") is not None and find(node, "k") is not None:
            eta = np.asarray(color_value(find(node, "eta")))
            k = np.asarray(color_value(find(node, "k")))
            f0 = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
        else:
            f0 = np.asarray(CONDUCTOR_F0.get(material, CONDUCTOR_F0["cu"]))
            if material not in CONDUCTOR_F0:
                warn(f"conductor material {material!r} unknown; using copper")
        scale, _ = _reflectance(node, ("specularReflectance",), ctx, (1.0, 1.0, 1.0))
        f0 = tuple(float(v) for v in np.clip(f0 * np.asarray(scale), 0.0, 1.0))
        warn(f"conductor {name!r}: Fresnel reflectance approximated by its normal-incidence value")
        if kind == "conductor":
            return Material(name, kind="mirror", specular=f0, albedo=f0, roughness=0.0)
        alpha = get_float(node, "alpha", 0.1)
        if find(node, "alphaU") is not None:
            alpha = float(np.sqrt(get_float(node, "alphaU", 0.1) * get_float(node, "alphaV", 0.1)))
            warn(f"anisotropic roughness of {name!r} approximated by the geometric mean")
        return Material(name, kind="conductor", specular=f0, albedo=f0, roughness=alpha)
    if kind in ("dielectric", "roughdielectric", "thindielectric"):
        if kind != "dielectric":
            warn(f"{kind} {name!r} approximated by a smooth dielectric")
        eta = _ior(node, "intIOR", 1.5046) / _ior(node, "extIOR", 1.000277)
        return Material(name, kind="dielectric", albedo=(1.0, 1.0, 1.0), ior=eta, roughness=0.0,
                        specular=(_f0_from_ior(eta),) * 3)
    if kind == "phong":
        albedo, texture = _reflectance(node, ("diffuseReflectance",), ctx, (0.5, 0.5, 0.5))
        spec, _ = _reflectance(node, ("specularReflectance",), ctx, (0.2, 0.2, 0.2))
        exponent = get_float(node, "exponent", 30.0)
        alpha = float(np.sqrt(2.0 / (exponent + 2.0)))
        warn(f"phong {name!r} approximated by plastic with GGX alpha {alpha:.3g}")
        return Material(name, kind="plastic", albedo=albedo, texture=texture, roughness=alpha, specular=spec)
    warn(f"bsdf type {kind!r} of {name!r} is not supported; using diffuse grey")
    return Material(name, albedo=(0.5, 0.5, 0.5))


def with_emission(material: Material, radiance, name: str) -> Material:
    """A copy of ``material`` that also emits ``radiance`` (an area light)."""
    return dataclasses.replace(material, name=name, emission=tuple(radiance))
