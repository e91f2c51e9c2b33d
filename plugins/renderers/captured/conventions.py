"""Conversion of captured channels to the harness's conventions (see ``harness.buffers``).

Each function takes the arrays as read (float32, rows top to bottom after :func:`flip_rows`) and
returns them in the harness's convention; a convention that already matches leaves the array
untouched, so harness-made captures read back bit for bit. Non-finite values are kept as they
are (the harness's non-finite policy sees them); only integer channels, which cannot hold them,
reject them.
"""

from __future__ import annotations

import numpy as np

#: linear ACEScg (AP1 primaries, D60) to linear sRGB / Rec.709 (D65), Bradford-adapted
ACESCG_TO_SRGB = np.array([
    [1.70505, -0.62179, -0.08326],
    [-0.13026, 1.14080, -0.01055],
    [-0.02400, -0.12897, 1.15297],
])
#: channels holding colours (converted between colour spaces)
COLOR_CHANNELS = frozenset({"color", "direct", "indirect", "albedo", "emission", "reference"})


def flip_rows(array: np.ndarray) -> np.ndarray:
    """Rows in the opposite order (an image stored bottom row first becomes top row first)."""
    return np.ascontiguousarray(array[::-1])


def color(array: np.ndarray, space: str) -> np.ndarray:
    """A colour (H, W, 3) in linear sRGB primaries from ``space`` (``linear_srgb`` or ``acescg``)."""
    if space == "linear_srgb":
        return array
    return (array.astype(np.float64) @ ACESCG_TO_SRGB.T).astype(np.float32)


def motion(array: np.ndarray, conventions: dict) -> np.ndarray:
    """Motion (H, W, 2) as ``previous - current`` image coordinates in pixels, y down.

    ``motion_vector``: ``previous_minus_current`` (harness, Cycles, Falcor) or
    ``current_minus_previous`` (a velocity); ``motion_units``: ``pixels``, ``uv`` (fractions of
    the image width and height) or ``ndc`` (the image spans 2 units each way); ``motion_y``:
    ``down`` or ``up`` (positive y towards the top of the image).
    """
    height, width = array.shape[:2]
    scale = np.ones(2)
    if conventions["motion_vector"] == "current_minus_previous":
        scale *= -1.0
    if conventions["motion_units"] == "uv":
        scale *= (width, height)
    elif conventions["motion_units"] == "ndc":
        scale *= (width / 2.0, height / 2.0)
    if conventions["motion_y"] == "up":
        scale[1] *= -1.0
    if np.array_equal(scale, (1.0, 1.0)):
        return array
    return (array.astype(np.float64) * scale).astype(np.float32)


def normal(array: np.ndarray, space: str, view: np.ndarray | None, encoding: str = "signed") -> np.ndarray:
    """World-space normals (H, W, 3) from ``space`` (``world``, or ``camera`` with the 4x4 world-to-camera ``view``).

    ``encoding``: ``signed`` (components in [-1, 1], as stored) or ``unsigned`` (``0.5 n + 0.5``,
    an image format without negative values): decoded as ``2 x - 1`` and renormalised (the
    storage is often quantised), pixels stored as zero staying zero (background).
    A normal transforms with the inverse transpose of the world-to-camera rotation ``R``, so
    ``n_world`` is along ``R^T n_camera``; the result is renormalised (zero stays zero).
    """
    if encoding == "unsigned":
        stored = array.astype(np.float64)
        background = ~(stored != 0).any(axis=-1, keepdims=True)
        array = _unit(np.where(background, 0.0, 2.0 * stored - 1.0)).astype(np.float32)
    if space == "world":
        return array
    rotation = np.asarray(view, np.float64)[:3, :3]
    return _unit(array.astype(np.float64) @ rotation).astype(np.float32)


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Vectors scaled to unit length (zero stays zero)."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(length > 0, vectors / np.where(length > 0, length, 1.0), vectors)


#: median length of a capture's non-zero normals must lie within this of 1
NORMAL_LENGTH_TOLERANCE = 0.1


def normal_length_problem(array: np.ndarray) -> str:
    """Why normals (H, W, 3, after conversion) are not unit length, or ``""`` when they are.

    Judged by the median length of the pixels with a non-zero finite normal (background is zero;
    averaged normals of antialiased edges may be shorter, which leaves the median near 1).
    """
    values = array.astype(np.float64).reshape(-1, 3)
    values = values[np.isfinite(values).all(axis=1)]
    length = np.linalg.norm(values, axis=1)
    length = length[length > 0]
    if length.size == 0:
        return ""
    median = float(np.median(length))
    if abs(median - 1.0) <= NORMAL_LENGTH_TOLERANCE:
        return ""
    hint = ""
    if (values >= 0).all():
        hint = '; every component is >= 0: if the file stores 0.5 n + 0.5, set normal_encoding = "unsigned"'
    return f"normals are not unit length (median length {median:.3g} over {length.size} pixels){hint}"


def depth(array: np.ndarray, conventions: dict, camera: dict) -> np.ndarray:
    """View-space depth (H, W): positive distance along the viewing axis, ``inf`` for background.

    ``depth``: ``view_z`` (as stored), ``ray_distance`` (from the eye to the hit; multiplied by
    the cosine between the pixel-centre ray and the axis, from the camera's ``fov_y`` or
    ``fov_x``), ``ndc_gl`` (OpenGL window z in [-1, 1]) or ``ndc_d3d`` (Direct3D/Vulkan z in
    [0, 1]), both from the camera's ``near`` and ``far``. Pixels equal to ``depth_background``
    (e.g. 0 for Mitsuba, 1e10 for Blender) become ``inf`` first.
    """
    kind = conventions["depth"]
    marker = conventions.get("depth_background")
    if kind == "view_z" and marker is None:
        return array
    values = array.astype(np.float64)
    background = values == np.float32(marker) if marker is not None else np.zeros(values.shape, bool)
    if kind == "ray_distance":
        values = values * _axis_cosine(camera, *array.shape)
    elif kind in ("ndc_gl", "ndc_d3d"):
        near, far = camera["near"], camera["far"]
        with np.errstate(divide="ignore", invalid="ignore"):
            if kind == "ndc_gl":
                values = 2.0 * near * far / ((far + near) - values * (far - near))
            else:
                values = near * far / (far - values * (far - near))
    values[background] = np.inf
    return values.astype(np.float32)


def _axis_cosine(camera: dict, height: int, width: int) -> np.ndarray:
    """cos(angle between each pixel-centre ray and the viewing axis), (H, W), for a pinhole camera."""
    aspect = width / height
    if "fov_y" in camera:
        tan_y = np.tan(np.radians(camera["fov_y"]) / 2.0)
        tan_x = tan_y * aspect
    else:
        tan_x = np.tan(np.radians(camera["fov_x"]) / 2.0)
        tan_y = tan_x / aspect
    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * tan_x
    y = (1.0 - (np.arange(height) + 0.5) / height * 2.0) * tan_y
    return 1.0 / np.sqrt(1.0 + x[None, :] ** 2 + y[:, None] ** 2)


def integer(array: np.ndarray) -> np.ndarray:
    """An integer channel (object id, spp) as int32 from float or uint storage.

    Raises
    ------
    ValueError
        Non-finite, fractional or out-of-range values (the message says which and how many).
    """
    if array.dtype.kind == "u":
        too_big = int(np.count_nonzero(array > np.iinfo(np.int32).max))
        if too_big:
            raise ValueError(f"{too_big} value(s) beyond the int32 range")
        return array.astype(np.int32)
    values = array.astype(np.float64)
    bad = int(np.count_nonzero(~np.isfinite(values)))
    if bad:
        raise ValueError(f"{bad} non-finite value(s) in an integer channel")
    fractional = int(np.count_nonzero(values != np.round(values)))
    if fractional:
        raise ValueError(f"{fractional} non-integer value(s) in an integer channel")
    info = np.iinfo(np.int32)
    if values.size and (values.min() < info.min or values.max() > info.max):
        raise ValueError("values beyond the int32 range")
    return values.astype(np.int32)
