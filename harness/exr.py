"""OpenEXR input and output through OpenImageIO, and the writer of capture folders.

OpenEXR is the exchange format of renderer outputs (AOVs): a file holds named float channels,
grouped into layers by a dotted prefix (``albedo.R``, ``albedo.G``, ``albedo.B``; Blender writes
``ViewLayer.Combined.R``). Everything here is float32: half channels are widened on reading,
``uint`` channels are read as their integer values (uint32), and files are written as float32
(lossless ZIP compression) unless ``half=True`` is asked for.

A *capture folder* is a sequence of frames as EXR files plus a sidecar (``capture.json``)
naming each file's layers and the conventions they follow; the ``captured`` renderer plugin reads
it. :func:`write_capture` writes any sequence of :class:`harness.Frame` and references in that
form, so that a captured folder and a built-in scene are interchangeable: reading it back gives
the same arrays bit for bit.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from harness.buffers import CHANNELS, Frame

#: the file name of the sidecar that :func:`write_capture` writes (the reader also accepts ``capture.toml``)
SIDECAR = "capture.json"
#: the value of the sidecar's ``format`` key
CAPTURE_FORMAT = "denoise-harness capture"
#: the version of the sidecar written (readers accept this and earlier versions)
CAPTURE_VERSION = 1
#: component names of each harness channel's layer in files written by :func:`write_capture`
COMPONENTS: Mapping[str, tuple[str, ...]] = {
    "color": ("R", "G", "B"),
    "direct": ("R", "G", "B"),
    "indirect": ("R", "G", "B"),
    "albedo": ("R", "G", "B"),
    "emission": ("R", "G", "B"),
    "normal": ("X", "Y", "Z"),
    "depth": ("Z",),
    "position": ("X", "Y", "Z"),
    "object_id": ("Y",),
    "motion": ("X", "Y"),
    "variance": ("R", "G", "B"),
    "spp": ("Y",),
    "visibility": ("Y",),
}
#: integer channels are stored as float32, which holds every integer up to this magnitude exactly
EXACT_INT = 2**24


class ExrError(OSError):
    """An EXR file cannot be read or written; the message names the file and the problem."""


def read_channels(path: str | Path) -> tuple[dict[str, np.ndarray], tuple[int, int]]:
    """Every channel of an OpenEXR file (or any image OpenImageIO reads).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    channels : dict of str to ndarray (H, W)
        Keyed by the full channel name (``"albedo.R"``); float32 for float and half channels
        (half widened exactly), uint32 for ``uint`` channels. With several parts (subimages),
        a channel name that repeats in a later part is prefixed with that part's name.
    size : (int, int)
        (width, height).

    Raises
    ------
    ExrError
        The file does not exist or cannot be decoded, its data window differs from its display
        window, or its parts differ in size.
    """
    import OpenImageIO as oiio

    path = Path(path)
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ExrError(f"{path}: cannot open: {_oiio_error(oiio)}")
    channels: dict[str, np.ndarray] = {}
    size = None
    try:
        subimage = 0
        while inp.seek_subimage(subimage, 0):
            spec = inp.spec()
            window = (spec.x, spec.y, spec.width, spec.height)
            display = (spec.full_x, spec.full_y, spec.full_width, spec.full_height)
            if window != display:
                raise ExrError(f"{path}: data window {window} differs from display window {display} (x, y, w, h)")
            if size is None:
                size = (spec.width, spec.height)
            elif size != (spec.width, spec.height):
                raise ExrError(f"{path}: part {subimage} is {spec.width}x{spec.height}, part 0 is {size[0]}x{size[1]}")
            formats = list(spec.channelformats) or [spec.format] * spec.nchannels
            part = spec.getattribute("name") or f"part{subimage}"
            pixels = inp.read_image(subimage, 0, 0, spec.nchannels, "float")
            if pixels is None:
                raise ExrError(f"{path}: cannot read pixels: {_oiio_error(oiio, inp)}")
            pixels = pixels.reshape(spec.height, spec.width, spec.nchannels)
            for c, name in enumerate(spec.channelnames):
                plane = pixels[..., c]
                if formats[c].basetype == oiio.UINT:  # float reads normalise integers: read the values
                    plane = inp.read_image(subimage, 0, c, c + 1, "uint")
                    if plane is None:
                        raise ExrError(f"{path}: cannot read channel {name!r}: {_oiio_error(oiio, inp)}")
                key = name if name not in channels else f"{part}.{name}"
                channels[key] = np.ascontiguousarray(plane.reshape(spec.height, spec.width))
            subimage += 1
    finally:
        inp.close()
    if size is None:
        raise ExrError(f"{path}: the file holds no image")
    return channels, size


def read_size(path: str | Path) -> tuple[int, int]:
    """(width, height) of an image file, from its header only; raises :class:`ExrError`."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ExrError(f"{path}: cannot open: {_oiio_error(oiio)}")
    try:
        spec = inp.spec()
        return spec.width, spec.height
    finally:
        inp.close()


def write_channels(path: str | Path, channels: Mapping[str, np.ndarray], *, half: bool = False) -> Path:
    """Write named (H, W) channels into one single-part OpenEXR file.

    Parameters
    ----------
    path : str or Path
        Parent folders are created.
    channels : mapping of str to ndarray (H, W)
        Full channel names (``"albedo.R"``) to float arrays of one size; written as float32
        (or half with ``half=True``), values unchanged (NaN and Inf included).
    half : bool
        Store 16-bit halves (lossy beyond 11 significant bits; never for bit-exact round trips).

    Returns
    -------
    Path

    Raises
    ------
    ExrError
        No channels, differing sizes, or the file cannot be written.
    """
    import OpenImageIO as oiio

    path = Path(path)
    if not channels:
        raise ExrError(f"{path}: nothing to write (no channels)")
    names = list(channels)
    arrays = [np.asarray(channels[n]) for n in names]
    shape = arrays[0].shape
    for name, array in zip(names, arrays):
        if array.ndim != 2 or array.shape != shape:
            raise ExrError(f"{path}: channel {name!r} has shape {array.shape}; every channel must be (H, W) = {shape}")
    pixels = np.ascontiguousarray(np.stack(arrays, axis=-1), dtype=np.float32)
    height, width = shape
    spec = oiio.ImageSpec(width, height, len(names), "half" if half else "float")
    spec.channelnames = tuple(names)
    spec.attribute("compression", "zip")
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise ExrError(f"{path}: cannot create: {_oiio_error(oiio)}")
    try:
        if not out.open(str(path), spec) or not out.write_image(pixels):
            raise ExrError(f"{path}: cannot write: {_oiio_error(oiio, out)}")
    finally:
        out.close()
    return path


def write_exr(path: str | Path, image: np.ndarray, *, half: bool = False) -> Path:
    """Write an image as a plain OpenEXR file (linear HDR, for viewers such as tev or ``iv``).

    Parameters
    ----------
    path : str or Path
    image : ndarray (H, W, 3), (H, W, C) or (H, W)
        Channels are named R, G, B (A for a fourth); one channel is Y; other counts are
        numbered ``"0"``, ``"1"``, ...
    half : bool
        Store halves instead of float32.

    Returns
    -------
    Path
    """
    image = np.asarray(image)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3:
        raise ExrError(f"{path}: an image must be (H, W) or (H, W, C), got shape {image.shape}")
    count = image.shape[2]
    names = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}.get(count, tuple(str(c) for c in range(count)))
    return write_channels(path, {n: image[..., c] for c, n in enumerate(names)}, half=half)


def layer_channels(layer: str, channel: str, array: np.ndarray) -> dict[str, np.ndarray]:
    """The EXR channels of one harness channel written as ``layer`` (names from :data:`COMPONENTS`).

    Integer channels (``object_id``, ``spp``) are stored as float32, exact up to
    :data:`EXACT_INT` in magnitude; larger values raise :class:`ExrError`.
    """
    array = np.asarray(array)
    if array.dtype.kind in "iu":
        if array.size and int(np.abs(array.astype(np.int64)).max()) > EXACT_INT:
            raise ExrError(f"channel {channel!r}: integers beyond {EXACT_INT} cannot be stored exactly as float32")
        array = array.astype(np.float32)
    components = COMPONENTS[channel]
    planes = array[..., None] if array.ndim == 2 else array
    return {f"{layer}.{c}": planes[..., k] for k, c in enumerate(components)}


def write_capture(
    folder: str | Path,
    frames: Sequence[Frame],
    references: Sequence[np.ndarray | None] | None = None,
    *,
    name: str | None = None,
    spp: int | None = None,
    reference_spp: int | None = None,
    reference_variances: Sequence[np.ndarray | None] | None = None,
    tags: Sequence[str] = (),
    tasks: Sequence[str] = ("denoise",),
    description: str = "",
    half: bool = False,
) -> Path:
    """Write a sequence as a capture folder that the ``captured`` renderer reads back exactly.

    Layout::

        folder/capture.json            the sidecar (preset "harness", frame metadata)
        folder/frames/0000.exr         every channel of frame 0 as a layer named after it
        folder/reference/0000.exr      the reference of frame 0 (R, G, B), when given, with its
                                       variance of the mean (layer ``variance``) when known

    Parameters
    ----------
    folder : str or Path
        Created if needed; files of the same names are overwritten.
    frames : sequence of Frame
        The frames in order (frame ``t`` of the capture is ``frames[t]``); every frame must have
        the same channels and size.
    references : sequence of ndarray (H, W, 3) or None, optional
        One converged reference per frame, or None (no references).
    name : str, optional
        Scene name stored in the sidecar (default: the first frame's ``meta.scene``, else the
        folder's name).
    spp, reference_spp : int, optional
        Samples per pixel of the frames and of the references, stored in the sidecar.
    reference_variances : sequence of ndarray (H, W, 3) or None, optional
        Each reference's per-pixel variance of the mean (all known, or the layer is not
        written), so that a run on the capture corrects its errors as the original run did.
    tags, tasks : sequence of str
        Scene tags and benchmark tasks stored in the sidecar.
    description : str
        One line stored in the sidecar.
    half : bool
        Store halves (smaller files; the round trip is then no longer exact).

    Returns
    -------
    Path
        The sidecar's path.

    Raises
    ------
    ValueError
        No frames, frames that differ in channels or size, references of the wrong count or shape.
    ExrError
        A file cannot be written.
    """
    folder = Path(folder)
    frames = list(frames)
    if not frames:
        raise ValueError(f"write_capture {folder}: no frames to write")
    first = frames[0]
    for t, frame in enumerate(frames):
        if frame.channels != first.channels or frame.shape != first.shape:
            raise ValueError(
                f"write_capture {folder}: frame {t} has channels {sorted(frame.channels)} at {frame.shape}, "
                f"frame 0 has {sorted(first.channels)} at {first.shape}"
            )
    if references is not None:
        references = list(references)
        if len(references) != len(frames):
            raise ValueError(f"write_capture {folder}: {len(references)} references for {len(frames)} frames")
        if all(r is None for r in references):
            references = None
    variances = None
    if references is not None and reference_variances is not None:
        variances = list(reference_variances)
        if len(variances) != len(references) or any(v is None for v in variances):
            variances = None  # the noise of some reference is unknown: state none
    channels = [c for c in CHANNELS if c in first.channels]
    for t, frame in enumerate(frames):
        planes: dict[str, np.ndarray] = {}
        for channel in channels:
            planes.update(layer_channels(channel, channel, frame[channel]))
        write_channels(folder / "frames" / f"{t:04d}.exr", planes, half=half)
        if references is not None:
            ref = references[t]
            want = (first.height, first.width, 3)
            if ref is None or np.shape(ref) != want:
                raise ValueError(f"write_capture {folder}: reference {t} must be {want}, got {np.shape(ref)}")
            planes = dict(zip("RGB", np.moveaxis(np.asarray(ref, np.float32), -1, 0)))
            if variances is not None:
                planes.update(layer_channels("variance", "variance", np.asarray(variances[t], np.float32)))
            write_channels(folder / "reference" / f"{t:04d}.exr", planes, half=half)
    sidecar = {
        "format": CAPTURE_FORMAT,
        "version": CAPTURE_VERSION,
        "name": name or first.meta.scene or folder.name,
        "description": description,
        "preset": "harness",
        "frames": len(frames),
        "file": "frames/{frame:04d}.exr",
        "channels": {c: c for c in channels},
        "tags": sorted(tags),
        "tasks": sorted(tasks),
        "frame": [frame.meta.to_dict() for frame in frames],
    }
    if spp is not None:
        sidecar["spp"] = int(spp)
    if references is not None:
        sidecar["reference"] = {"file": "reference/{frame:04d}.exr", "layer": ""}
        if variances is not None:
            sidecar["reference"]["variance"] = "variance"
        if reference_spp is not None:
            sidecar["reference"]["spp"] = int(reference_spp)
    path = folder / SIDECAR
    path.write_text(json.dumps(sidecar, indent=1) + "\n")
    return path


def _oiio_error(oiio, obj=None) -> str:
    message = (obj.geterror() if obj is not None else "") or oiio.geterror()
    return " ".join(message.split()) or "unknown error"
