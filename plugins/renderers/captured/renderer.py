"""The ``captured`` renderer: serves frames and references stored in a capture folder.

A captured scene (see :func:`open_capture`) is a :class:`harness.Scene` of kind ``"captured"``
whose ``params`` hold the resolved sidecar, the channels the capture has
(``params["channels"]``) and a digest of every file it reads, so a changed file changes the
scene's ``content_hash`` and misses the render cache; ``source`` is the folder. A capture with
two half-buffers of the colour (``color_halves``) serves ``color`` (their mean, or the stored
colour checked against it) and ``variance`` (:func:`.halves.half_variance`).
"""

from __future__ import annotations

import hashlib

import numpy as np

from harness import CHANNELS, Frame, FrameMeta, Scene, read_size

from .halves import half_variance, mean_of_halves
from .reader import FrameReader
from .sidecar import HALVES_KEY, Capture, CaptureError, find_sidecar, load_sidecar, source_label

#: the channels that guide the averaging window of a variance from half-buffers
VARIANCE_GUIDES = ("normal", "albedo", "depth")

#: the scene kind of captured folders
KIND = "captured"


def open_capture(path) -> Scene | None:
    """The captured scene of a folder (or sidecar file), or None when ``path`` has no sidecar.

    Checks every frame's files up front: each must exist inside the capture folder and have the
    size of frame 0's colour (or of its first half-buffer); frame 0's reference (and its variance)
    layer must be there, its normals unit length, its half-buffers readable and of one size, and
    its colour, where the sidecar gives both, the mean of the half-buffers. Errors about a file
    the sidecar names start with the sidecar's line.

    Raises
    ------
    CaptureError
        One line naming the file and the problem.
    """
    sidecar = find_sidecar(path)
    if sidecar is None:
        return None
    capture = load_sidecar(sidecar)
    reader = FrameReader(capture)
    sources = reader.available(0)
    reference = capture.reference
    if reference is not None and not reference.required and not capture.path(reference, 0).is_file():
        reference = None
    halves = capture.color_halves or ()
    sized = sources.get("color") or halves[0]  # the colour, or its first half-buffer
    if not capture.path(sized, 0).is_file():
        raise CaptureError(f"{capture.where(sized.channel)}: {capture.path(sized, 0)}: missing file for frame 0 "
                           f"({source_label(sized.channel)})")
    width, height = read_size(capture.path(sized, 0))
    files = []
    for t in range(capture.frames):
        for source in [*sources.values(), *halves, *([reference] if reference else [])]:
            file = capture.path(source, t)
            if file in files:
                continue
            if not file.is_file():
                raise CaptureError(f"{capture.where(source.channel)}: {file}: missing file for frame {t} "
                                   f"({source_label(source.channel)})")
            size = _size(file)
            if size != (width, height):
                raise CaptureError(f"{capture.where(source.channel)}: {file}: {size[0]}x{size[1]} pixels, but the "
                                   f"colour of frame 0 is {width}x{height} ({source_label(source.channel)})")
            files.append(file)
    _check_first_frame(capture, reader, sources, reference)
    digest = hashlib.sha256()
    for file in files:
        digest.update(str(file.relative_to(capture.folder)).encode())
        digest.update(hashlib.sha256(file.read_bytes()).digest())
    params = {
        "format": "captured",
        "capture": capture.describe(),
        "channels": sorted(set(sources) | ({"color", "variance"} if halves else set())),
        "references": reference is not None,
        "tasks": list(capture.tasks),
        "files_sha256": digest.hexdigest(),
    }
    return _scene(capture, params, (width, height))


def _check_first_frame(capture: Capture, reader: FrameReader, sources: dict, reference) -> None:
    """Read what only a read can check, once, at open: the reference's layers, the normals and the
    half-buffers of frame 0."""
    if capture.color_halves is not None:
        reader.halves(0, sources.get("color"))  # its errors name the sidecar's line
    checks = []
    if reference is not None:
        checks.append(("reference", reader.reference))
        if capture.reference_variance is not None:
            checks.append(("reference", reader.reference_variance))
    if "normal" in sources:
        checks.append(("normal", lambda t: reader.read(t, {"normal": sources["normal"]})))
    for key, read in checks:
        try:
            read(0)
        except CaptureError as exc:
            raise CaptureError(f"{capture.where(key)}: {exc}") from None


def _size(file) -> tuple[int, int]:
    try:
        return read_size(file)
    except OSError as exc:
        raise CaptureError(f"{file}: unreadable: {str(exc).removeprefix(f'{file}: ')}") from None


def _scene(capture: Capture, params: dict, resolution: tuple) -> Scene:
    """A Scene of kind "captured" that gives only the channels the capture holds."""
    return Scene(
        name=capture.name,
        kind=KIND,
        frame_count=capture.frames,
        resolution=resolution,
        tags=frozenset(capture.tags) | {"captured"},
        params=params,
        source=str(capture.folder),
        channels=frozenset(params["channels"]),
    )


class CapturedRenderer:
    """Reads the frames of captured scenes (``open_capture``); makes nothing new.

    The noisy frames carry the samples they were captured with: ``spp`` must match the
    sidecar's ``spp`` where it states one; ``seed`` is ignored (a capture holds one
    realisation of the noise). ``render`` returns the asked channels that the capture has
    (the planner skips filters needing the others, from ``scene.channels``).
    """

    def settings(self) -> dict:
        return {}

    def _capture(self, scene) -> Capture:
        if getattr(scene, "kind", None) != KIND:
            raise ValueError(f"captured renderer reads captured scenes only; {scene.name!r} is {scene.kind!r}")
        return load_sidecar(find_sidecar(scene.source))

    def _check_resolution(self, scene, resolution) -> None:
        if resolution is not None and tuple(resolution) != tuple(scene.resolution):
            raise ValueError(
                f"captured scene {scene.name!r} is {scene.resolution[0]}x{scene.resolution[1]}; "
                f"it cannot be served at {resolution[0]}x{resolution[1]} (run it at its own resolution)"
            )

    def _index(self, capture: Capture, frame_index: int) -> None:
        if not 0 <= frame_index < capture.frames:
            raise ValueError(f"captured scene {capture.name!r} has frames 0..{capture.frames - 1}, not {frame_index}")

    def render(
        self, scene, frame_index: int, *, spp: int = 1, seed: int = 0, channels=frozenset(), resolution=None
    ) -> Frame:
        """The captured frame ``frame_index`` with the asked ``channels`` that the capture has (and ``color``)."""
        capture = self._capture(scene)
        self._check_resolution(scene, resolution)
        self._index(capture, frame_index)
        if capture.spp is not None and spp != capture.spp:
            raise ValueError(
                f"captured scene {scene.name!r} holds {capture.spp}-spp frames; asked for {spp} spp "
                f"(run it with --spp {capture.spp})"
            )
        have = set(scene.params["channels"])
        wanted = (set(channels) & have) | {"color"}
        reader = FrameReader(capture)
        read = set(wanted)
        if capture.color_halves is not None and "variance" in wanted:
            read |= set(VARIANCE_GUIDES) & have
        sources = {c: capture.sources[c] for c in CHANNELS if c in read and c in capture.sources}
        arrays = reader.read(frame_index, sources)
        if capture.color_halves is not None:
            arrays.update(self._from_halves(capture, reader, frame_index, arrays, wanted))
        arrays = {c: arrays[c] for c in CHANNELS if c in wanted}
        meta = self._meta(capture, scene, frame_index, arrays["color"].shape)
        return Frame(arrays, meta, owner="renderer 'captured'")

    @staticmethod
    def _from_halves(capture: Capture, reader: FrameReader, t: int, arrays: dict, wanted: set) -> dict:
        """``color`` (the stored one, checked, or the mean) and, if wanted, ``variance`` from the half-buffers."""
        a, b = reader.halves(t, capture.sources.get("color"))
        other = next(iter(arrays.values()), None)
        if other is not None and other.shape[:2] != a.shape[:2]:
            raise CaptureError(f"{capture.where(HALVES_KEY)}: frame {t}: the half-buffers are {a.shape[1]}x"
                               f"{a.shape[0]}, the other channels {other.shape[1]}x{other.shape[0]}")
        out = {} if "color" in arrays else {"color": mean_of_halves(a, b)}
        if "variance" in wanted:
            out["variance"] = half_variance(a, b, {g: arrays.get(g) for g in VARIANCE_GUIDES})
        return out

    def reference(self, scene, frame_index: int, *, spp: int = 0, seed: int = 0, resolution=None) -> np.ndarray:
        """The captured reference of ``frame_index`` (``spp`` and ``seed`` are ignored)."""
        capture = self._capture(scene)
        self._check_resolution(scene, resolution)
        self._index(capture, frame_index)
        if not scene.params["references"]:
            raise ValueError(f"captured scene {scene.name!r} has no references (no 'reference' in its sidecar)")
        ref = FrameReader(capture).reference(frame_index)
        want = (scene.resolution[1], scene.resolution[0], 3)
        if ref.shape != want:
            raise CaptureError(
                f"{capture.path(capture.reference, frame_index)}: reference is {ref.shape[1]}x{ref.shape[0]}, "
                f"the frames are {want[1]}x{want[0]}"
            )
        return ref

    def reference_variance(self, scene, frame_index: int) -> np.ndarray | None:
        """The captured reference's per-pixel variance of the mean, or None where the capture
        does not state it (the reference's noise is then unknown, never taken as zero)."""
        capture = self._capture(scene)
        self._index(capture, frame_index)
        if not scene.params["references"]:
            return None
        variance = FrameReader(capture).reference_variance(frame_index)
        want = (scene.resolution[1], scene.resolution[0], 3)
        if variance is not None and variance.shape != want:
            raise CaptureError(f"{capture.path(capture.reference_variance, frame_index)}: reference variance is "
                               f"{variance.shape[1]}x{variance.shape[0]}, the frames are {want[1]}x{want[0]}")
        return variance

    @staticmethod
    def _meta(capture: Capture, scene, frame_index: int, shape) -> FrameMeta:
        """The frame's metadata: the sidecar's entry when it has one, else defaults."""
        entry = dict(capture.frame_meta[frame_index]) if capture.frame_meta else {}
        entry.pop("view", None)
        entry.setdefault("index", frame_index)
        entry.setdefault("scene", scene.name)
        entry.setdefault("camera_cut", frame_index == 0)
        if capture.spp is not None:
            entry.setdefault("extra", {"samples": capture.spp * shape[0] * shape[1]})
        return FrameMeta.from_dict(entry)
