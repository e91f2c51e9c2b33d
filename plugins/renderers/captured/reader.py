"""Reading one captured frame: files, layers, components, sizes, conventions.

Every problem is a :class:`CaptureError` whose one line names the file and what is wrong.
Non-finite values are kept as read and reported with a :class:`CaptureWarning` naming the file
and layer; the harness's non-finite policy (``raise`` or ``repair``) then decides.
"""

from __future__ import annotations

import warnings

import numpy as np

from harness import ExrError, read_channels

from . import conventions as conv
from . import halves as hv
from .sidecar import Capture, CaptureError, Source, source_size

#: component names tried, in order, when a source does not list them (by channel size)
COMPONENT_ORDERS = {
    3: (("R", "G", "B"), ("X", "Y", "Z"), ("r", "g", "b"), ("x", "y", "z")),
    2: (("X", "Y"), ("R", "G"), ("U", "V"), ("x", "y"), ("u", "v")),
    1: (("Z",), ("Y",), ("R",), ("X",), ("T",), ("I",), ("V",)),
}


class CaptureWarning(UserWarning):
    """A captured file holds NaN or Inf values (kept as read; the harness's policy decides)."""


def layers_of(names) -> list[str]:
    """The layer names (channel-name prefixes) of a file's channels; ``""`` for unprefixed ones."""
    return sorted({n.rsplit(".", 1)[0] if "." in n else "" for n in names})


def components_of(names, layer: str) -> dict[str, str]:
    """Component name -> full channel name, for the channels of ``layer``."""
    if layer:
        prefix = layer + "."
        return {n[len(prefix):]: n for n in names if n.startswith(prefix) and "." not in n[len(prefix):]}
    return {n: n for n in names if "." not in n}


class FrameReader:
    """Reads the channels and reference of a capture's frames (each file read once per frame).

    Parameters
    ----------
    capture : Capture
    """

    def __init__(self, capture: Capture):
        self.capture = capture

    def available(self, t: int = 0) -> dict[str, Source]:
        """The sources present in frame ``t``'s files: optional preset channels that are absent
        are left out; a required one that is absent raises :class:`CaptureError`."""
        files: dict = {}
        present = {}
        for channel, source in self.capture.sources.items():
            path = self.capture.path(source, t)
            if not source.required and not path.is_file():
                continue
            planes, _ = self._file(files, path)
            if not source.required and not components_of(planes, source.layer):
                continue
            self._take(files, source, t)  # the layer and its components must be there
            present[channel] = source
        return present

    def read(self, t: int, sources: dict[str, Source]) -> dict[str, np.ndarray]:
        """The harness arrays of ``sources`` in frame ``t``, converted to the harness's conventions."""
        files: dict = {}
        raw = {}
        for channel, source in sources.items():
            raw[channel] = self._take(files, source, t)
        size = {a.shape[:2] for a in raw.values()}
        if len(size) > 1:
            detail = ", ".join(
                f"{c} {a.shape[1]}x{a.shape[0]} ({self.capture.path(sources[c], t).name})" for c, a in raw.items()
            )
            raise CaptureError(f"{self.capture.folder}: frame {t}: AOV sizes differ: {detail}")
        out = {}
        for channel, array in raw.items():
            out[channel] = self._convert(channel, array, t, sources[channel])
            self._warn_nonfinite(channel, out[channel], t, sources[channel])
        return out

    def halves(self, t: int, color: Source | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The two half-buffers of frame ``t``, (H, W, 3) float32 each in linear sRGB primaries.

        Raises
        ------
        CaptureError
            A half-buffer cannot be read, their sizes differ or, given the ``color`` source, the
            colour (as stored) is not their mean; the line starts with the sidecar's
            ``color_halves`` line.
        """
        first, second = self.capture.color_halves
        where = self.capture.where(first.channel)
        files: dict = {}
        try:
            raw = [self._take(files, source, t) for source in (first, second)]
            stored = None if color is None else self._take(files, color, t)
        except CaptureError as exc:
            raise CaptureError(f"{where}: {exc}") from None
        if raw[0].shape != raw[1].shape:
            names = [self.capture.path(s, t).name for s in (first, second)]
            raise CaptureError(f"{where}: frame {t}: the half-buffers differ in size: {raw[0].shape[1]}x"
                               f"{raw[0].shape[0]} ({names[0]}) and {raw[1].shape[1]}x{raw[1].shape[0]} ({names[1]})")
        if stored is not None:
            if stored.shape != raw[0].shape:
                raise CaptureError(f"{where}: frame {t}: the colour is {stored.shape[1]}x{stored.shape[0]}, "
                                   f"its half-buffers {raw[0].shape[1]}x{raw[0].shape[0]}")
            problem = hv.mean_mismatch(stored.astype(np.float32), *(h.astype(np.float32) for h in raw))
            if problem:
                raise CaptureError(f"{where}: frame {t}: {problem}")
        out = []
        for source, array in zip((first, second), raw):
            half = self._convert("color", array, t, source)
            self._warn_nonfinite("color", half, t, source)
            out.append(half)
        return out[0], out[1]

    def reference(self, t: int) -> np.ndarray:
        """The reference image of frame ``t``, (H, W, 3) float32 in linear sRGB primaries."""
        source = self.capture.reference
        array = self._take({}, source, t)
        out = self._convert("reference", array, t, source)
        self._warn_nonfinite("reference", out, t, source)
        return out

    def reference_variance(self, t: int) -> np.ndarray | None:
        """The reference's per-pixel variance of the mean in frame ``t`` (H, W, 3), or None."""
        source = self.capture.reference_variance
        if source is None:
            return None
        out = self._convert("variance", self._take({}, source, t), t, source)
        self._warn_nonfinite("variance", out, t, source)
        return out

    # ----------------------------------------------------------------------------- internals
    def _file(self, files: dict, path) -> tuple[dict, tuple]:
        if path not in files:
            if not path.is_file():
                raise CaptureError(f"{path}: missing file (expected by {self.capture.sidecar.name})")
            try:
                files[path] = read_channels(path)
            except ExrError as exc:
                raise CaptureError(f"{path}: unreadable: {str(exc).removeprefix(f'{path}: ')}") from None
        return files[path]

    def _take(self, files: dict, source: Source, t: int) -> np.ndarray:
        """The components of ``source`` in frame ``t`` as (H, W, k) (or (H, W) for one component)."""
        path = self.capture.path(source, t)
        names, _ = self._file(files, path)
        found = components_of(names, source.layer)
        what = f"channel {source.channel!r}" if source.channel != "reference" else "the reference"
        if not found:
            raise CaptureError(
                f"{path}: no layer {source.layer!r} for {what}; layers in the file: {layers_of(names)}"
            )
        size = source_size(source.channel)
        order = source.components or self._pick(found, size)
        if order is None or any(c not in found for c in order):
            raise CaptureError(
                f"{path}: layer {source.layer!r} for {what} has components {sorted(found)}; "
                f"cannot take {list(order) if order else size} (give 'components' in the sidecar)"
            )
        planes = [names[found[c]] for c in order]
        kinds = {p.dtype.kind for p in planes}
        if len(kinds) > 1:
            raise CaptureError(f"{path}: layer {source.layer!r} mixes integer and float components")
        return planes[0] if size == 1 else np.stack(planes, axis=-1)

    @staticmethod
    def _pick(found: dict, size: int) -> tuple | None:
        if size == 1 and len(found) == 1:
            return tuple(found)
        for order in COMPONENT_ORDERS[size]:
            if all(c in found for c in order):
                return order
        return None

    def _convert(self, channel: str, array: np.ndarray, t: int, source: Source) -> np.ndarray:
        c = self.capture.conventions
        if c["origin"] == "bottom_left":
            array = conv.flip_rows(array)
        if channel in ("object_id", "spp"):
            try:
                return conv.integer(array)
            except ValueError as exc:
                path = self.capture.path(source, t)
                raise CaptureError(f"{path}: layer {source.layer!r} ({channel}): {exc}") from None
        if array.dtype.kind == "u":
            array = array.astype(np.float32)
        if channel in conv.COLOR_CHANNELS:
            return conv.color(array, c["color_space"])
        if channel == "variance" and c["color_space"] != "linear_srgb":
            raise CaptureError(
                f"{self.capture.path(source, t)}: a variance in {c['color_space']} cannot be converted to linear sRGB "
                "without the covariances; store it in linear_srgb"
            )
        if channel == "motion":
            return conv.motion(array, c)
        if channel == "normal":
            array = conv.normal(array, c["normal_space"], self.capture.view(t), c["normal_encoding"])
            problem = conv.normal_length_problem(array)
            if problem:
                raise CaptureError(f"{self.capture.path(source, t)}: layer {source.layer!r} (normal): {problem}")
            return array
        if channel == "depth":
            return conv.depth(array, c, self.capture.camera)
        return array

    def _warn_nonfinite(self, channel: str, array: np.ndarray, t: int, source: Source) -> None:
        if array.dtype.kind != "f":
            return
        bad = ~np.isfinite(array)
        if channel == "depth":
            bad &= ~np.isposinf(array)
        count = int(np.count_nonzero(bad))
        if count:
            nan = int(np.count_nonzero(np.isnan(array)))
            warnings.warn(
                f"{self.capture.path(source, t)}: layer {source.layer!r} ({channel}) holds {count} non-finite "
                f"value(s) ({nan} NaN, {count - nan} Inf); kept as read for the harness's non-finite policy",
                CaptureWarning,
                stacklevel=3,
            )
