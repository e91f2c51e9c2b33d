"""Hosek-Wilkie sun and sky (Mitsuba 3's ``sunsky`` emitter), evaluated from their published coefficients.

The coefficients (Hosek and Wilkie 2012, 2013; BSD licence) are not part of this project: they are
read at run time from the installed Mitsuba 3 package (``mitsuba/data/sunsky/sunsky_datasets.bin``,
a Mitsuba tensor file; the ``validate`` extra installs it). :func:`load_tables` says why when they
cannot be read, and the loader then keeps its gradient approximation.

What is evaluated (Mitsuba 3's RGB variants; ``docs/pathtracer.md`` has the equations): in the
emitter's local frame (z up; ``to_world`` maps it to the world), a direction ``w`` at ``cos theta
= w_z`` and at angle ``gamma`` from the sun, with the sun at elevation ``eta``,

- the sky: ``sky_scale / 106.7502594 * L_M (1 + A exp(B / (cos theta + 0.01))) (C + D exp(E gamma)
  + F cos^2 gamma + G chi(H, gamma) + I sqrt(cos theta))`` per channel, black below the horizon,
  where the 9 parameters and ``L_M`` are the datasets interpolated linearly in turbidity (10
  levels, 1 to 10) and in ground albedo (0 and 1, per channel), then by the quintic Bezier curve
  of 6 control points in ``x = (eta / (pi / 2))^(1/3)``;
- the sun, within ``r = sun_aperture / 2`` of its direction and above the horizon: by default
  (``complex_sun`` false) uniform, ``sun_scale * area_ratio * 467.069280386 * rgb(E) / (2 pi (1 -
  cos r0))``, with ``E`` the tabulated solar irradiance spectrum (``sampling_data.bin``: 11
  wavelengths) interpolated linearly in turbidity and in the sun's elevation (2, 5, ..., 89
  degrees), ``rgb`` Mitsuba's ``spectrum_to_srgb``, ``r0 = 0.5358 / 2`` degrees and ``area_ratio =
  (1 - cos r0) / (1 - cos r)`` (any aperture keeps the real sun's irradiance); with
  ``complex_sun``, ``sun_scale * area_ratio * 467.069280386 / 106.7502594 * sum_k sum_j x^k
  cos(psi)^j R[seg, k, j]``, a piecewise polynomial over 45 segments of the direction's own
  elevation (``x`` the elevation past the segment's start) whose ``cos(psi)`` powers hold the limb
  darkening (``cos psi = sqrt(1 - sin^2 gamma / sin^2 r)``), ``R`` interpolated linearly in
  turbidity.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Mitsuba 3's default ``sun_aperture`` (degrees), the sun's apparent diameter
SUN_APERTURE = 0.5358
#: ``1 / MI_CIE_Y_NORMALIZATION`` of Mitsuba 3: its RGB variants divide the model's values by this
CIE_Y_INTEGRAL = 106.7502593994140625
#: Mitsuba 3's conversion of the RGB solar dataset to its RGB radiance (``SPEC_TO_RGB_SUN_CONV``)
SUN_RGB_CONVERSION = 467.069280386
#: the datasets inside the Mitsuba package
DATASET = ("data", "sunsky", "sunsky_datasets.bin")
FIELDS = {"sky_params": "sky_params_rgb", "sky_radiance": "sky_rad_rgb", "sun_radiance": "sun_rad_rgb"}
IRRADIANCE = ("data", "sunsky", "sampling_data.bin")
IRRADIANCE_FIELDS = {"sun_irradiance": "sun_irradiance"}
#: wavelengths (nm) of the spectral tables
WAVELENGTHS = tuple(float(w) for w in range(320, 721, 40))
FLOAT_TENSORS = {"Float16": "TensorXf16", "Float32": "TensorXf", "Float64": "TensorXf64"}
SHAPES = {"sky_params": (10, 2, 6, 3, 9), "sky_radiance": (10, 2, 6, 3), "sun_radiance": (10, 45, 3, 4, 6),
          "sun_irradiance": (10, 30, 11), "spectrum_to_rgb": (3, 11)}
#: Mitsuba 0.6's sun and sky are y-up; Mitsuba 3's sunsky is z-up: this ``to_world`` (a rotation of
#: -90 degrees about x) gives a Mitsuba 3 sunsky the orientation of a Mitsuba 0.6 file's
Y_UP = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0))
INSTALL_HINT = 'install Mitsuba 3 with the validate extra: pip install -e ".[validate]"'


@dataclass(frozen=True)
class SunskyParams:
    """Parameters of a Mitsuba 3 ``sunsky`` emitter (its names and defaults).

    Attributes
    ----------
    sun_direction : (float, float, float)
        World direction towards the sun (normalised here).
    turbidity : float
        In [1, 10].
    albedo : (float, float, float)
        Ground albedo per channel, in [0, 1].
    sky_scale, sun_scale : float
    sun_aperture : float
        The sun's apparent diameter, degrees.
    complex_sun : bool
        Mitsuba 3's ``complex_sun``: the limb-darkened solar radiance instead of its default, a
        uniform disc of the tabulated solar irradiance.
    to_world : 3x3 tuple
        The emitter's rotation: its local z (the zenith) maps to ``to_world @ (0, 0, 1)``.
    """

    sun_direction: tuple = (0.0, 0.0, 1.0)
    turbidity: float = 3.0
    albedo: tuple = (0.3, 0.3, 0.3)
    sky_scale: float = 1.0
    sun_scale: float = 1.0
    sun_aperture: float = SUN_APERTURE
    complex_sun: bool = False
    to_world: tuple = field(default=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)))

    def __post_init__(self):
        d = np.asarray(self.sun_direction, float)
        d = d / max(float(np.linalg.norm(d)), 1e-300)
        object.__setattr__(self, "sun_direction", tuple(float(v) for v in d))
        object.__setattr__(self, "albedo", tuple(float(v) for v in np.broadcast_to(self.albedo, 3)))
        object.__setattr__(self, "complex_sun", bool(self.complex_sun))
        object.__setattr__(self, "to_world", tuple(tuple(float(v) for v in row)
                                                   for row in np.asarray(self.to_world, float).reshape(3, 3)))

    def to_local(self, directions: np.ndarray) -> np.ndarray:
        """World directions (..., 3) in the emitter's frame, normalised (Mitsuba's ``to_world^-1 d``)."""
        inverse = np.linalg.inv(np.asarray(self.to_world, float))
        local = np.asarray(directions, float) @ inverse.T
        return local / np.maximum(np.linalg.norm(local, axis=-1, keepdims=True), 1e-300)

    @property
    def sun_local(self) -> np.ndarray:
        """The sun's direction in the emitter's frame."""
        return self.to_local(np.asarray(self.sun_direction))

    @property
    def sun_elevation(self) -> float:
        """The sun's elevation above the emitter's horizon, radians."""
        return float(math.asin(min(max(self.sun_local[2], -1.0), 1.0)))

    @property
    def half_aperture(self) -> float:
        """Half the sun's aperture, radians."""
        return math.radians(0.5 * self.sun_aperture)


def dataset_folder():
    """The folder of the sunsky data of the importable Mitsuba package, and a reason when there is none.

    Returns
    -------
    folder : pathlib.Path or None
    reason : str
        Empty when ``folder`` holds both data files.
    """
    try:
        import mitsuba
    except ImportError:
        return None, f"Mitsuba 3 is not installed ({INSTALL_HINT})"
    root = Path(mitsuba.__file__).parent
    for parts in (DATASET, IRRADIANCE):
        if not root.joinpath(*parts).is_file():
            version = getattr(mitsuba, "__version__", "?")
            return None, (f"the installed Mitsuba {version} has no {'/'.join(parts)} (a Mitsuba 3 with the "
                          f"sunsky emitter has; {INSTALL_HINT})")
    return root.joinpath(*DATASET[:-1]), ""


@functools.lru_cache(maxsize=1)
def load_tables():
    """The RGB datasets of the Hosek-Wilkie model from the installed Mitsuba 3, or None and why.

    Returns
    -------
    tables : dict or None
        float64 arrays: ``sky_params`` (10 turbidities, 2 albedos, 6 Bezier control points, 3
        channels, 9 parameters), ``sky_radiance`` (10, 2, 6, 3), ``sun_radiance`` (10 turbidities,
        45 elevation segments, 3 channels, 4 polynomial degrees, 6 limb-darkening powers),
        ``sun_irradiance`` (10 turbidities, 30 sun elevations 2, 5, ..., 89 degrees, 11
        wavelengths), ``spectrum_to_rgb`` (3, 11): Mitsuba's ``spectrum_to_srgb`` of spectra
        sampled at :data:`WAVELENGTHS` (see :func:`spectrum_to_rgb_weights`).
    reason : str
        Why ``tables`` is None (empty otherwise).
    """
    folder, reason = dataset_folder()
    if folder is None:
        return None, reason
    try:
        tables = read_tensor_file(folder / DATASET[-1], FIELDS)
        tables.update(read_tensor_file(folder / IRRADIANCE[-1], IRRADIANCE_FIELDS))
        tables["spectrum_to_rgb"] = spectrum_to_rgb_weights()
    except (OSError, ValueError, KeyError, AttributeError) as exc:
        return None, f"the sunsky data of the installed Mitsuba could not be read ({exc}; {INSTALL_HINT})"
    for name, shape in SHAPES.items():
        if tables[name].shape != shape:
            return None, (f"the sunsky data of the installed Mitsuba: {name} has shape {tables[name].shape}, "
                          f"expected {shape} (a Mitsuba version this harness does not know)")
    return tables, ""


def spectrum_to_rgb_weights() -> np.ndarray:
    """(3, 11): linear sRGB of a spectrum sampled at :data:`WAVELENGTHS`, as Mitsuba's ``spectrum_to_srgb``.

    The mean over the samples of Mitsuba's CIE 1931 curves (normalised by their Y integral,
    :data:`CIE_Y_INTEGRAL`) times the values, then its XYZ-to-sRGB matrix (both read from the
    installed package).
    """
    import mitsuba.scalar_rgb as variant

    xyz = np.array([list(variant.cie1931_xyz(w)) for w in WAVELENGTHS], float).T / (len(WAVELENGTHS) * CIE_Y_INTEGRAL)
    matrix = np.array([list(variant.xyz_to_srgb(list(e))) for e in np.eye(3)], float).T
    return matrix @ xyz


def read_tensor_file(path, fields: dict) -> dict:
    """Named fields of a Mitsuba tensor file as float64 arrays (``fields``: our name -> the file's name).

    ``mitsuba.TensorFile`` reads the file; each field is converted to the Dr.Jit tensor type of its
    own float type, then to NumPy.
    """
    import drjit
    import mitsuba

    tensors = mitsuba.TensorFile(str(path))
    out = {}
    for ours, theirs in fields.items():
        if theirs not in tensors:
            raise KeyError(f"no field {theirs!r}")
        item = tensors[theirs]
        kind = str(item.dtype).rsplit(".", 1)[-1]
        if kind not in FLOAT_TENSORS:
            raise ValueError(f"field {theirs!r} has type {kind}, not a float type")
        out[ours] = np.array(item.to(getattr(drjit.scalar, FLOAT_TENSORS[kind])), dtype=np.float64)
    return out


def _lerp_axis0(data: np.ndarray, position: float) -> np.ndarray:
    """Linear interpolation along the first axis at the fractional index ``position`` (clamped)."""
    last = data.shape[0] - 1
    position = min(max(float(position), 0.0), float(last))
    lo = min(int(math.floor(position)), last)
    hi = min(lo + 1, last)
    f = position - lo
    return (1.0 - f) * data[lo] + f * data[hi]


def bezier_weights(elevation: float) -> np.ndarray:
    """Weights of the 6 control points at the sun's ``elevation`` (radians): quintic Bernstein in ``x``.

    ``x = (elevation / (pi / 2))^(1/3)``, kept below 1 as Mitsuba does (``1 - 2^-24``).
    """
    x = math.pow(max(elevation, 0.0) / (0.5 * math.pi), 1.0 / 3.0)
    x = min(x, 1.0 - 2.0 ** -24)
    return np.array([math.comb(5, i) * x ** i * (1.0 - x) ** (5 - i) for i in range(6)])


def sky_coefficients(tables: dict, turbidity: float, albedo, elevation: float) -> tuple[np.ndarray, np.ndarray]:
    """The sky model's 9 parameters (3, 9) and mean radiance ``L_M`` (3,) per RGB channel.

    Interpolated linearly in ``turbidity`` (levels 1 to 10) and, per channel, in ``albedo`` between
    the ground albedos 0 and 1, then by the Bezier curve in the sun's ``elevation``.
    """
    albedo = np.clip(np.broadcast_to(np.asarray(albedo, float), 3), 0.0, 1.0)
    weights = bezier_weights(elevation)
    out = []
    for name in ("sky_params", "sky_radiance"):
        by_albedo = _lerp_axis0(tables[name], turbidity - 1.0)  # (2, 6, 3, ...)
        a = albedo.reshape((1, 3) + (1,) * (by_albedo.ndim - 3))
        mixed = (1.0 - a) * by_albedo[0] + a * by_albedo[1]  # (6, 3, ...)
        out.append(np.tensordot(weights, mixed, axes=(0, 0)))
    return out[0], out[1]


def unit_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between unit vectors (..., 3), accurate near 0 and pi (``2 asin(|a -+ b| / 2)``)."""
    dot = np.sum(a * b, axis=-1)
    near = 2.0 * np.arcsin(np.minimum(0.5 * np.linalg.norm(a - b, axis=-1), 1.0))
    far = math.pi - 2.0 * np.arcsin(np.minimum(0.5 * np.linalg.norm(a + b, axis=-1), 1.0))
    return np.where(dot >= 0.0, near, far)


def sky_radiance(params: SunskyParams, tables: dict, local: np.ndarray) -> np.ndarray:
    """RGB sky radiance (N, 3) towards local unit directions ``local`` (N, 3), Mitsuba 3's RGB scale."""
    local = np.asarray(local, float).reshape(-1, 3)
    out = np.zeros((len(local), 3))
    elevation = params.sun_elevation
    if elevation < 0.0 or params.sky_scale == 0.0:
        return out
    coef, mean = sky_coefficients(tables, params.turbidity, params.albedo, elevation)
    cos_theta = local[:, 2]
    up = cos_theta >= 0.0
    ct = cos_theta[up][:, None]
    gamma = unit_angle(local[up], params.sun_local[None, :])[:, None]
    cos_gamma = np.cos(gamma)
    a, b, c, d, e, f, g, i, h = (coef[:, k][None, :] for k in range(9))
    chi = (1.0 + cos_gamma ** 2) / np.power(1.0 + h * h - 2.0 * h * cos_gamma, 1.5)
    first = 1.0 + a * np.exp(b / (ct + 0.01))
    second = c + d * np.exp(e * gamma) + f * cos_gamma ** 2 + g * chi + i * np.sqrt(ct)
    out[up] = params.sky_scale / CIE_Y_INTEGRAL * first * second * mean[None, :]
    return out


def area_ratio(half_aperture: float) -> float:
    """Mitsuba 3's factor keeping the sun's irradiance when its half aperture is ``half_aperture`` (radians)."""
    return (1.0 - math.cos(math.radians(0.5 * SUN_APERTURE))) / (1.0 - math.cos(half_aperture))


def sun_irradiance_rgb(params: SunskyParams, tables: dict) -> np.ndarray:
    """Mitsuba 3's default (``complex_sun`` false) RGB solar radiance, uniform over the disc.

    The tabulated solar irradiance spectrum, interpolated linearly in turbidity and in the sun's
    elevation (at 2, 5, ..., 89 degrees), converted to RGB and spread over the real sun's solid angle:
    ``sun_scale * area_ratio * 467.069280386 * rgb(E) / (2 pi (1 - cos r0))``.
    """
    if params.sun_elevation < 0.0 or params.sun_scale == 0.0:
        return np.zeros(3)
    by_elevation = _lerp_axis0(tables["sun_irradiance"], params.turbidity - 1.0)  # (30, 11)
    spectrum = _lerp_axis0(by_elevation, (math.degrees(params.sun_elevation) - 2.0) / 3.0)
    solid_angle = 2.0 * math.pi * (1.0 - math.cos(math.radians(0.5 * SUN_APERTURE)))
    rgb = tables["spectrum_to_rgb"] @ spectrum
    return params.sun_scale * area_ratio(params.half_aperture) * SUN_RGB_CONVERSION * rgb / solid_angle


def sun_radiance(params: SunskyParams, tables: dict, local: np.ndarray) -> np.ndarray:
    """RGB solar radiance (N, 3) towards local unit directions (N, 3): zero outside the disc and below the horizon.

    Uniform (:func:`sun_irradiance_rgb`) by default; with ``complex_sun`` the limb-darkened
    piecewise polynomial of the module's docstring.
    """
    local = np.asarray(local, float).reshape(-1, 3)
    out = np.zeros((len(local), 3))
    if params.sun_elevation < 0.0 or params.sun_scale == 0.0:
        return out
    r = params.half_aperture
    sun = params.sun_local
    hit = (local[:, 2] >= 0.0) & (local @ sun >= math.cos(r))
    if not hit.any():
        return out
    if not params.complex_sun:
        out[hit] = sun_irradiance_rgb(params, tables)
        return out
    coef = _lerp_axis0(tables["sun_radiance"], params.turbidity - 1.0)  # (45, 3, 4, 6)
    segments = coef.shape[0]
    elevation = 0.5 * math.pi - np.arccos(np.clip(local[hit, 2], -1.0, 1.0))
    seg = np.minimum(np.floor(np.cbrt(elevation / (0.5 * math.pi)) * segments).astype(int), segments - 1)
    seg = np.maximum(seg, 0)
    x = elevation - 0.5 * math.pi * (seg / segments) ** 3
    gamma = unit_angle(local[hit], sun[None, :])
    cos_psi = np.sqrt(np.maximum(1.0 - (np.sin(gamma) / math.sin(r)) ** 2, 0.0))
    powers_x = x[:, None] ** np.arange(coef.shape[2])[None, :]  # (n, 4)
    powers_psi = cos_psi[:, None] ** np.arange(coef.shape[3])[None, :]  # (n, 6)
    value = np.einsum("nckj,nk,nj->nc", coef[seg], powers_x, powers_psi)
    out[hit] = params.sun_scale * area_ratio(r) * SUN_RGB_CONVERSION / CIE_Y_INTEGRAL * value
    return out


def radiance(params: SunskyParams, tables: dict, directions: np.ndarray) -> np.ndarray:
    """Mitsuba 3's ``sunsky`` radiance (sky plus sun, RGB) arriving from world directions (N, 3)."""
    local = params.to_local(np.asarray(directions, float).reshape(-1, 3))
    return sky_radiance(params, tables, local) + sun_radiance(params, tables, local)


def map_directions(height: int) -> np.ndarray:
    """World directions (height, 2 height, 3) of the texel centres of a harness environment map.

    The harness's convention: row ``v = acos(d_y) / pi``, column ``u = 0.5 + atan2(d_x, -d_z) / (2 pi)``.
    """
    width = 2 * height
    theta = (np.arange(height) + 0.5) / height * math.pi
    phi = ((np.arange(width) + 0.5) / width - 0.5) * 2.0 * math.pi
    st = np.sin(theta)[:, None]
    return np.stack([st * np.sin(phi)[None, :], np.broadcast_to(np.cos(theta)[:, None], (height, width)),
                     -st * np.cos(phi)[None, :]], axis=-1)


def bake_sky(params: SunskyParams, tables: dict, height: int = 256) -> np.ndarray:
    """The sky (without the sun) as a harness environment map (height, 2 height, 3) float32.

    Each texel holds the radiance towards its centre (the path tracer reads maps by nearest texel
    and importance-samples them by luminance).
    """
    d = map_directions(height)
    local = params.to_local(d.reshape(-1, 3))
    return np.ascontiguousarray(sky_radiance(params, tables, local).reshape(d.shape), np.float32)


def cone_directions(axis: np.ndarray, half_angle: float, rings: int = 128, sectors: int = 64) -> np.ndarray:
    """Directions (rings * sectors, 3) of equal solid angle covering the cone around unit ``axis``.

    Midpoints of a grid uniform in ``cos`` (rings) and azimuth (sectors).
    """
    axis = np.asarray(axis, float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(axis, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(axis, t1)
    cos_t = 1.0 - (np.arange(rings) + 0.5) / rings * (1.0 - math.cos(half_angle))
    phi = (np.arange(sectors) + 0.5) / sectors * 2.0 * math.pi
    ct, ph = np.meshgrid(cos_t, phi, indexing="ij")
    st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
    d = (st * np.cos(ph))[..., None] * t1 + (st * np.sin(ph))[..., None] * t2 + ct[..., None] * axis
    return d.reshape(-1, 3)


def sun_disc_radiance(params: SunskyParams, tables: dict) -> np.ndarray:
    """The mean RGB solar radiance over the sun's disc (without the sky).

    A uniform disc of this radiance and the sun's aperture has the power of Mitsuba 3's sun; it is
    Mitsuba's own radiance for the default uniform sun wholly above the horizon.
    """
    local = cone_directions(params.sun_local, params.half_aperture * (1.0 - 1e-9))
    return sun_radiance(params, tables, local).mean(axis=0)


__all__ = ["SUN_APERTURE", "SunskyParams", "bake_sky", "load_tables", "radiance", "sky_coefficients",
           "sky_radiance", "sun_disc_radiance", "sun_irradiance_rgb", "sun_radiance"]
