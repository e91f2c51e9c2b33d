"""The capture sidecar: parsing, presets and validation.

The sidecar (``capture.toml`` or ``capture.json`` in the capture folder) says which files and
layers hold each harness channel and which conventions they follow; ``docs/captured.md`` is its
reference. :func:`load_sidecar` turns it into a :class:`Capture` with every preset default
resolved, or raises :class:`CaptureError` with one line naming the sidecar and the problem.

A sidecar is untrusted input: a file pattern takes the frame number only (``{frame}`` or an
integer format such as ``{frame:04d}``; no attribute or item access), and every file it names
must lie inside the capture folder once resolved, unless the environment variable
:data:`ALLOW_ENV` is ``1``.

The ``channels`` table may also hold :data:`HALVES_KEY`: two sources of the colour, each a render
of the frame with half of its samples (``.halves`` derives the colour and the ``variance``
channel from them).
"""

from __future__ import annotations

import json
import math
import os
import re
import string
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness import CHANNELS, TASKS

from .presets import HARNESS_CONVENTIONS, PRESETS

#: sidecar file names looked for in a capture folder, in this order
SIDECAR_NAMES = ("capture.toml", "capture.json")
#: set to ``1`` to let a sidecar name files outside its capture folder
ALLOW_ENV = "DENOISE_HARNESS_ALLOW_OUTSIDE_FILES"
#: the format specs a file pattern's ``{frame}`` may take: integers, optionally zero-padded
FRAME_SPEC = re.compile(r"0?[0-9]{0,3}d?")
#: the ``channels`` key naming the two half-buffers of the colour
HALVES_KEY = "color_halves"

TOP_KEYS = frozenset({
    "format", "version", "name", "description", "preset", "frames", "first_frame", "file", "spp",
    "channels", "reference", "conventions", "camera", "frame", "tags", "tasks",
})
SOURCE_KEYS = frozenset({"file", "layer", "components"})
CAMERA_KEYS = frozenset({"fov_y", "fov_x", "near", "far", "view"})
FRAME_KEYS = frozenset(
    {"index", "scene", "seed", "view_proj", "prev_view_proj", "jitter", "camera_cut", "extra", "view"}
)
#: convention -> accepted values (the first is the harness's own; ``depth_background`` is a number)
CONVENTION_VALUES = {
    "motion_vector": ("previous_minus_current", "current_minus_previous"),
    "motion_units": ("pixels", "uv", "ndc"),
    "motion_y": ("down", "up"),
    "normal_space": ("world", "camera"),
    "normal_encoding": ("signed", "unsigned"),
    "depth": ("view_z", "ray_distance", "ndc_gl", "ndc_d3d"),
    "color_space": ("linear_srgb", "acescg"),
    "origin": ("top_left", "bottom_left"),
}


class CaptureError(ValueError):
    """A capture folder or its sidecar is unusable; the message names the file and the problem."""


@dataclass(frozen=True)
class Source:
    """Where one channel (or the reference) of every frame is stored.

    Attributes
    ----------
    channel : str
        Harness channel name, or ``"reference"``.
    file : str
        File name pattern relative to the capture folder; ``{frame}`` is the frame number.
    layer : str
        Layer (channel-name prefix before the component) in the file; ``""`` for unprefixed
        channels such as a plain ``R, G, B`` file.
    components : tuple of str or None
        Component names to take, in order; None picks them by the channel's size.
    required : bool
        False for a channel (or reference) that only a preset names: absent from the capture, it
        is not provided.
    """

    channel: str
    file: str
    layer: str = ""
    components: tuple | None = None
    required: bool = True


@dataclass(frozen=True)
class Capture:
    """A parsed sidecar with presets applied.

    Attributes
    ----------
    folder, sidecar : Path
    name, description : str
    preset : str
    frames : int
        Number of frames; frame ``t`` is stored under file number ``first_frame + t``.
    first_frame : int
    spp : int or None
        Samples per pixel of the noisy colour, when stated.
    sources : dict of str to Source
        Channel sources (``color`` always among them).
    reference : Source or None
    reference_spp : int or None
    reference_variance : Source or None
        The reference's per-pixel variance of the mean (a layer of the reference's file, in
        linear sRGB), when the sidecar's reference names one.
    conventions : dict
        Every convention, the harness's defaults filled in.
    camera : dict
        ``fov_y``/``fov_x`` (degrees), ``near``, ``far``, ``view`` (4x4 world-to-camera).
    color_halves : tuple of two Source, or None
        Two independent renders of each frame with half of the colour's samples each (channels
        ``color_halves[0]`` and ``color_halves[1]``), when the sidecar names them: the colour is
        their mean (``sources`` has ``color`` only when the sidecar also names it, to be checked
        against the mean) and they give the ``variance`` channel.
    frame_meta : list of dict
        Per-frame metadata (``FrameMeta.to_dict()`` keys plus ``view``); empty when not given.
    tags, tasks : tuple of str
    """

    folder: Path
    sidecar: Path
    name: str
    description: str
    preset: str
    frames: int
    first_frame: int
    spp: int | None
    sources: dict
    reference: Source | None
    reference_spp: int | None
    reference_variance: Source | None
    conventions: dict
    camera: dict
    color_halves: tuple | None = None
    frame_meta: list = field(default_factory=list)
    tags: tuple = ()
    tasks: tuple = ("denoise",)
    lines: dict = field(default_factory=dict)

    def path(self, source: Source, t: int) -> Path:
        """The file holding ``source`` in frame ``t`` (0-based): inside the capture folder.

        Raises
        ------
        CaptureError
            The file lies outside the folder (and :data:`ALLOW_ENV` is not ``1``).
        """
        name = source.file.format(frame=self.first_frame + t)
        path = self.folder / name
        if os.environ.get(ALLOW_ENV, "") != "1":
            root, target = self.folder.resolve(), path.resolve()
            if root not in target.parents:
                raise CaptureError(f"{self.where(source.channel)}: the file {name!r} of "
                                   f"{source_label(source.channel)} is outside the capture folder {self.folder} "
                                   f"(set {ALLOW_ENV}=1 to allow it)")
        return path

    def where(self, key: str) -> str:
        """The sidecar and, where known, the line that declares ``key`` (``capture.toml:12``)."""
        line = self.lines.get(key.split("[", 1)[0])
        return f"{self.sidecar}:{line}" if line else str(self.sidecar)

    def view(self, t: int) -> np.ndarray | None:
        """World-to-camera matrix of frame ``t`` (its own, else the sidecar's camera), or None."""
        entry = self.frame_meta[t] if self.frame_meta else {}
        view = entry.get("view", self.camera.get("view"))
        return None if view is None else np.asarray(view, np.float64)

    def describe(self) -> dict:
        """The resolved capture as JSON-able data (hashed into the scene's identity)."""
        def source(s: Source | None):
            return None if s is None else {"file": s.file, "layer": s.layer, "components": s.components}

        return {
            "name": self.name,
            "preset": self.preset,
            "frames": self.frames,
            "first_frame": self.first_frame,
            "spp": self.spp,
            "sources": {c: source(s) for c, s in sorted(self.sources.items())},
            "reference": source(self.reference),
            "reference_spp": self.reference_spp,
            "reference_variance": source(self.reference_variance),
            "color_halves": None if self.color_halves is None else [source(s) for s in self.color_halves],
            "conventions": dict(sorted(self.conventions.items())),
            "camera": self.camera,
            "frame_meta": self.frame_meta,
        }


def find_sidecar(path: Path) -> Path | None:
    """The sidecar of ``path`` (a capture folder, or the sidecar file itself), or None."""
    path = Path(path)
    if path.is_file():
        return path if path.name in SIDECAR_NAMES else None
    for name in SIDECAR_NAMES:
        if (path / name).is_file():
            return path / name
    return None


def source_label(channel: str) -> str:
    """How error messages name a source's channel (``channel 'albedo'``, ``the reference``)."""
    if channel.startswith(HALVES_KEY):
        return f"the colour's half-buffer {channel!r}"
    return "the reference" if channel == "reference" else f"channel {channel!r}"


def source_size(channel: str) -> int:
    """Components of a source's channel: 3 for the reference and the colour's half-buffers."""
    return 3 if channel == "reference" or channel.startswith(HALVES_KEY) else CHANNELS[channel][0]


def key_lines(text: str) -> dict:
    """Line numbers (1-based) of the first line declaring each key or table of a sidecar's text.

    Recognises ``[name]``, ``name = ...`` (TOML) and ``"name": ...`` (JSON), so channels (``color
    = ...``) and ``reference`` are found in either form.
    """
    lines: dict = {}
    for number, line in enumerate(text.splitlines(), 1):
        found = re.match(r'\s*(?:\[+\s*"?([A-Za-z_][\w.]*)"?\s*\]|"?([A-Za-z_]\w*)"?\s*[=:])', line)
        if found:
            lines.setdefault(found.group(1) or found.group(2), number)
    return lines


def load_sidecar(sidecar: Path) -> Capture:
    """Parse and validate a sidecar; raises :class:`CaptureError` naming it and the problem."""
    sidecar = Path(sidecar)
    data = _read(sidecar)
    where = str(sidecar)
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise CaptureError(f"{where}: unknown key(s) {unknown}; known keys: {sorted(TOP_KEYS)}")
    preset_name = data.get("preset", "harness")
    if preset_name not in PRESETS:
        raise CaptureError(f"{where}: unknown preset {preset_name!r}; presets: {sorted(PRESETS)}")
    preset = PRESETS[preset_name]
    frames = data.get("frames")
    if not isinstance(frames, int) or isinstance(frames, bool) or frames < 1:
        raise CaptureError(f"{where}: 'frames' must be a positive integer (the number of frames), got {frames!r}")
    first_frame = _integer(where, "first_frame", data.get("first_frame", preset.get("first_frame", 0)))
    default_file = data.get("file", preset.get("file"))
    declared_channels = _table(where, "channels", data, {})
    halves = _halves(where, declared_channels.get(HALVES_KEY), default_file)
    declared_channels = {c: e for c, e in declared_channels.items() if c != HALVES_KEY}
    sources = _sources(where, declared_channels, preset["channels"], default_file)
    if halves is not None:
        sources = _with_halves(where, sources, declared_channels)
    declared = "reference" in data
    reference_entry = data.get("reference", preset.get("reference"))
    reference, reference_spp = _reference(where, reference_entry, default_file, declared)
    reference_variance = _reference_variance(where, reference_entry, reference)
    conventions = _conventions(where, {**preset["conventions"], **_table(where, "conventions", data, {})})
    camera = _camera(where, _table(where, "camera", data, {}))
    frame_meta = _frame_meta(where, data.get("frame", []), frames)
    _check_camera_needs(where, conventions, camera, frame_meta)
    if "color" not in sources and halves is None:
        raise CaptureError(f"{where}: no source for the 'color' channel (a capture needs the noisy colour, or "
                           f"its two half-buffers in '{HALVES_KEY}')")
    tasks = tuple(sorted(_strings(where, "tasks", data.get("tasks", ["denoise"]))))
    if not tasks or set(tasks) - set(TASKS):
        raise CaptureError(f"{where}: 'tasks' must be a non-empty subset of {list(TASKS)}, got {list(tasks)}")
    spp = data.get("spp")
    return Capture(
        folder=sidecar.parent,
        sidecar=sidecar,
        name=str(data.get("name") or sidecar.parent.name),
        description=str(data.get("description", "")),
        preset=preset_name,
        frames=frames,
        first_frame=first_frame,
        spp=None if spp is None else _positive(where, "spp", spp),
        sources=sources,
        reference=reference,
        reference_spp=reference_spp,
        reference_variance=reference_variance,
        conventions=conventions,
        color_halves=halves,
        camera=camera,
        frame_meta=frame_meta,
        tags=tuple(sorted(_strings(where, "tags", data.get("tags", [])))),
        tasks=tasks,
        lines=key_lines(sidecar.read_text(errors="replace")),
    )


def _read(sidecar: Path) -> dict:
    try:
        text = sidecar.read_text()
    except OSError as exc:
        raise CaptureError(f"{sidecar}: cannot read the sidecar: {exc.strerror or exc}") from None
    try:
        if sidecar.suffix == ".toml":
            if sys.version_info < (3, 11):
                raise CaptureError(f"{sidecar}: TOML sidecars need Python 3.11 or later; write capture.json instead")
            import tomllib

            data = tomllib.loads(text)
        else:
            data = json.loads(text)
    except (ValueError, TypeError) as exc:
        if isinstance(exc, CaptureError):
            raise
        raise CaptureError(f"{sidecar}: not valid {sidecar.suffix[1:].upper()}: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict):
        raise CaptureError(f"{sidecar}: the sidecar must be a table (object) of keys")
    return data


def _table(where: str, key: str, data: dict, default):
    value = data.get(key, default)
    if not isinstance(value, dict):
        raise CaptureError(f"{where}: {key!r} must be a table, got {type(value).__name__}")
    return value


def _integer(where: str, key: str, value) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise CaptureError(f"{where}: {key!r} must be an integer, got {value!r}")
    return value


def _positive(where: str, key: str, value) -> int:
    if _integer(where, key, value) < 1:
        raise CaptureError(f"{where}: {key!r} must be >= 1, got {value!r}")
    return value


def _strings(where: str, key: str, value) -> list:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise CaptureError(f"{where}: {key!r} must be a list of strings, got {value!r}")
    return value


def _source(where: str, channel: str, entry, default_file: str | None, required: bool) -> Source:
    """One ``channels`` entry: a layer name (in the default file) or ``{file, layer, components}``."""
    if isinstance(entry, str):
        entry = {"layer": entry}
    if not isinstance(entry, dict):
        raise CaptureError(f"{where}: channel {channel!r} must be a layer name or a table, got {entry!r}")
    allowed = SOURCE_KEYS | ({"spp", "variance"} if channel == "reference" else set())
    unknown = sorted(set(entry) - allowed)
    if unknown:
        raise CaptureError(f"{where}: {channel!r} has unknown key(s) {unknown}; keys: {sorted(allowed)}")
    file = entry.get("file", default_file)
    if not isinstance(file, str) or not file:
        raise CaptureError(f"{where}: channel {channel!r} names no file (give 'file' here or at the top level)")
    _check_pattern(where, channel, file)
    layer = entry.get("layer", "")
    if not isinstance(layer, str):
        raise CaptureError(f"{where}: the layer of channel {channel!r} must be a string, got {layer!r}")
    components = entry.get("components")
    if components is not None:
        size = source_size(channel)
        names_ok = isinstance(components, list) and all(isinstance(c, str) for c in components)
        if not names_ok or len(components) != size:
            raise CaptureError(
                f"{where}: 'components' of channel {channel!r} must list {size} component name(s), got {components!r}"
            )
        components = tuple(components)
    return Source(channel, file, layer, components, required)


def _check_pattern(where: str, channel: str, file: str) -> None:
    """A file pattern may hold ``{frame}`` with an integer format spec only (``{frame:04d}``)."""
    try:
        fields = list(string.Formatter().parse(file))
    except ValueError as exc:
        raise CaptureError(f"{where}: file pattern {file!r} of {source_label(channel)} is not valid: {exc}") from None
    for _, name, spec, conversion in fields:
        if name is None:
            continue
        if name != "frame" or conversion is not None or not FRAME_SPEC.fullmatch(spec or ""):
            field_text = name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "")
            raise CaptureError(f"{where}: file pattern {file!r} of {source_label(channel)} may only hold {{frame}} "
                               f"or an integer format of it such as {{frame:04d}}, not {{{field_text}}}")


def _sources(where: str, declared: dict, preset: dict, default_file: str | None) -> dict:
    unknown = sorted(set(declared) - set(CHANNELS))
    if unknown:
        raise CaptureError(f"{where}: unknown channel(s) {unknown}; harness channels: {sorted(CHANNELS)} "
                           f"and '{HALVES_KEY}'")
    sources = {}
    for channel in CHANNELS:
        if channel in declared:
            entry = declared[channel]
            if entry is False:
                continue
            sources[channel] = _source(where, channel, entry, default_file, required=True)
        elif channel in preset:
            sources[channel] = _source(where, channel, preset[channel], default_file, required=channel == "color")
    return sources


def _halves(where: str, entry, default_file: str | None) -> tuple | None:
    """The two half-buffer sources of ``color_halves``: each a layer name or ``{file, layer, components}``."""
    if entry is None:
        return None
    if not isinstance(entry, list) or len(entry) != 2:
        raise CaptureError(f"{where}: '{HALVES_KEY}' must list two sources of the colour (each a layer name or "
                           f"a table of file, layer, components), got {entry!r}")
    halves = tuple(_source(where, f"{HALVES_KEY}[{i}]", e, default_file, required=True) for i, e in enumerate(entry))
    if halves[0].file == halves[1].file and halves[0].layer == halves[1].layer:
        raise CaptureError(f"{where}: the two sources of '{HALVES_KEY}' are the same layer {halves[0].layer!r} of "
                           f"{halves[0].file!r}; they must be two independent renders")
    return halves


def _with_halves(where: str, sources: dict, declared: dict) -> dict:
    """Channel sources beside ``color_halves``: the colour only where the sidecar itself names it
    (checked against the halves' mean), no ``variance`` (the halves give it)."""
    if "variance" in declared and declared["variance"] is not False:
        raise CaptureError(f"{where}: give either a 'variance' channel or '{HALVES_KEY}' (which gives the "
                           "variance), not both")
    keep = {c: s for c, s in sources.items() if c != "variance"}
    if "color" not in declared or declared["color"] is False:
        keep.pop("color", None)
    return keep


def _reference(where: str, entry, default_file: str | None, required: bool) -> tuple[Source | None, int | None]:
    if entry is None or entry is False:
        return None, None
    if isinstance(entry, str):
        entry = {"layer": entry}
    if not isinstance(entry, dict):
        raise CaptureError(f"{where}: 'reference' must be a layer name or a table, got {entry!r}")
    spp = entry.get("spp")
    source = _source(where, "reference", entry, default_file, required)
    return source, None if spp is None else _positive(where, "reference spp", spp)


def _reference_variance(where: str, entry, reference: Source | None) -> Source | None:
    """The reference's per-pixel variance of the mean: a layer of the reference's file, if named."""
    layer = entry.get("variance") if isinstance(entry, dict) and reference is not None else None
    if layer is None:
        return None
    if not isinstance(layer, str) or not layer:
        raise CaptureError(f"{where}: the reference's 'variance' must be a layer name, got {layer!r}")
    return Source("variance", reference.file, layer, None, reference.required)


def _conventions(where: str, given: dict) -> dict:
    conventions = dict(HARNESS_CONVENTIONS)
    for key, value in given.items():
        if key == "depth_background":
            if not isinstance(value, (int, float)) or isinstance(value, bool) or math.isnan(value):
                raise CaptureError(f"{where}: convention 'depth_background' must be a number, got {value!r}")
            conventions[key] = float(value)
        elif key in CONVENTION_VALUES:
            if value not in CONVENTION_VALUES[key]:
                raise CaptureError(
                    f"{where}: convention {key!r} must be one of {list(CONVENTION_VALUES[key])}, got {value!r}"
                )
            conventions[key] = value
        else:
            raise CaptureError(
                f"{where}: unknown convention {key!r}; conventions: {sorted([*CONVENTION_VALUES, 'depth_background'])}"
            )
    return conventions


def _matrix(where: str, what: str, value) -> list:
    array = np.asarray(value, dtype=np.float64) if isinstance(value, list) else None
    if array is None or array.shape != (4, 4) or not np.isfinite(array).all():
        raise CaptureError(f"{where}: {what} must be a 4x4 matrix of finite numbers (list of 4 rows)")
    return array.tolist()


def _camera(where: str, camera: dict) -> dict:
    unknown = sorted(set(camera) - CAMERA_KEYS)
    if unknown:
        raise CaptureError(f"{where}: camera has unknown key(s) {unknown}; keys: {sorted(CAMERA_KEYS)}")
    out = {}
    for key in ("fov_y", "fov_x", "near", "far"):
        if key in camera:
            value = camera[key]
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not 0 < value < math.inf:
                raise CaptureError(f"{where}: camera {key!r} must be a positive number, got {value!r}")
            out[key] = float(value)
    if "fov_y" in out and "fov_x" in out:
        raise CaptureError(f"{where}: camera gives both 'fov_y' and 'fov_x'; give one")
    if "near" in out and "far" in out and not out["near"] < out["far"]:
        raise CaptureError(f"{where}: camera 'near' ({out['near']}) must be less than 'far' ({out['far']})")
    if "view" in camera:
        out["view"] = _matrix(where, "camera 'view'", camera["view"])
    return out


def _frame_meta(where: str, entries, frames: int) -> list:
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise CaptureError(f"{where}: 'frame' must be a list of tables (one per frame)")
    if entries and len(entries) != frames:
        raise CaptureError(f"{where}: 'frame' has {len(entries)} entries for {frames} frames")
    for t, entry in enumerate(entries):
        unknown = sorted(set(entry) - FRAME_KEYS)
        if unknown:
            raise CaptureError(f"{where}: frame {t} has unknown key(s) {unknown}; keys: {sorted(FRAME_KEYS)}")
        for key in ("view", "view_proj", "prev_view_proj"):
            if entry.get(key) is not None:
                _matrix(where, f"frame {t} {key!r}", entry[key])
    return [dict(e) for e in entries]


def _check_camera_needs(where: str, conventions: dict, camera: dict, frame_meta: list) -> None:
    per_frame = bool(frame_meta) and all("view" in e for e in frame_meta)
    if conventions["normal_space"] == "camera" and "view" not in camera and not per_frame:
        raise CaptureError(f"{where}: camera-space normals need the world-to-camera 'view' matrix "
                           "(in [camera] or in every [[frame]])")
    if conventions["depth"] == "ray_distance" and "fov_y" not in camera and "fov_x" not in camera:
        raise CaptureError(f"{where}: depth 'ray_distance' needs the camera's field of view ('fov_y' or 'fov_x')")
    if conventions["depth"].startswith("ndc") and ("near" not in camera or "far" not in camera):
        raise CaptureError(f"{where}: depth {conventions['depth']!r} needs the camera's 'near' and 'far'")

