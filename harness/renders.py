"""The render store: scenes, renderers, noisy frames and converged references, through the cache.

It owns the scene and renderer instances of a process, the one function that makes cache keys
(:meth:`RenderStore.key`), and the two things a run needs rendered: :meth:`RenderStore.frame`
and :meth:`RenderStore.reference` (chunked and resumable where the renderer declares
``chunked``). ``denoise-bench run``, ``render`` and ``bench`` all go through it.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from harness.buffers import ChannelError, Frame
from harness.cache import Cache, make_key
from harness.protocols import check_renderer

#: seed of every reference render: independent of the noisy frames' seeds
REFERENCE_SEED = 1_000_003
#: samples per checkpoint of a chunked reference
DEFAULT_CHUNK = 64


class RenderStore:
    """Scenes, renderers and their cached output.

    Parameters
    ----------
    registry : harness.Registry
    cache : harness.cache.Cache, optional
        Where renders and references are kept (a disabled cache when None).
    resolution : (width, height), optional
        Override of every scene's default resolution.
    renderer_settings : mapping name -> dict, optional
        Keyword arguments of each renderer's factory.
    """

    def __init__(self, registry, cache: Cache | None = None, *, resolution=None, renderer_settings=None):
        self.registry = registry
        self.cache = cache if cache is not None else Cache(enabled=False)
        self.resolution_override = tuple(resolution) if resolution is not None else None
        self._settings = {k: dict(v) for k, v in (renderer_settings or {}).items()}
        self._scenes: dict = {}
        self._opened: dict = {}
        self._renderers: dict = {}

    def at_resolution(self, resolution) -> RenderStore:
        """A store rendering every scene at ``resolution`` that shares this one's cache, scenes and renderers."""
        other = RenderStore(self.registry, self.cache, resolution=resolution, renderer_settings=self._settings)
        other._scenes, other._opened, other._renderers = self._scenes, self._opened, self._renderers
        return other

    # ----------------------------------------------------------------- scenes and renderers
    def add_scene(self, scene, path: str | Path | None = None) -> None:
        """Make a scene built outside the registry (e.g. opened from a folder) known by name."""
        self._scenes[scene.name] = scene
        if path is not None:
            self._opened[scene.name] = str(path)

    def scene(self, name: str):
        """The scene called ``name``, built once from its spec (or added with :meth:`add_scene`)."""
        if name not in self._scenes:
            self._scenes[name] = self.registry.get("scene", name).factory()
        return self._scenes[name]

    def scene_hash(self, name: str) -> str:
        return self.scene(name).content_hash()

    def scene_approximations(self, names) -> dict[str, list[str]]:
        """What each scene of ``names`` that this store has built approximates, as its plugin reports
        it in ``Scene.params["approximations"]`` (e.g. a Mitsuba feature rendered approximately);
        scenes with none, or not built in this process, are left out."""
        out = {}
        for name in names:
            scene = self._scenes.get(name)
            notes = (getattr(scene, "params", None) or {}).get("approximations") if scene is not None else None
            if notes:
                out[name] = [str(n) for n in notes]
        return out

    def scene_path(self, name: str) -> str | None:
        """The folder a scene was opened from, or None for a registered scene."""
        return self._opened.get(name)

    def renderer(self, name: str):
        """The renderer called ``name``, built once, checked against what its spec declares."""
        if name not in self._renderers:
            spec = self.registry.get("renderer", name)
            renderer = spec.factory(**self._settings.get(name, {}))
            check_renderer(spec, renderer)
            self._renderers[name] = renderer
        return self._renderers[name]

    def renderer_settings(self, name: str) -> dict:
        """What the renderer reports as its settings (part of cache keys and job identities)."""
        return dict(self.renderer(name).settings())

    def factory_settings(self, name: str) -> dict:
        """The keyword arguments the renderer was built with (to build an equal one elsewhere)."""
        return dict(self._settings.get(name, {}))

    def resolution(self, scene) -> tuple[int, int]:
        """(width, height) frames of ``scene`` are rendered at."""
        return tuple(self.resolution_override or scene.resolution)

    def resolution_of(self, scene_spec) -> tuple[int, int]:
        """(width, height) of a scene from its spec (without building it)."""
        return tuple(self.resolution_override or scene_spec.resolution)

    # ----------------------------------------------------------------- cache keys
    def key(self, what: str, scene, renderer: str, frame_index: int, **extra) -> str:
        """The cache key of one stored render: every input that changes its arrays.

        Parameters
        ----------
        what : str
            ``frame`` or ``reference`` (chunk checkpoints share their reference's key).
        scene : Scene
        renderer : str
        frame_index : int
        **extra
            The rest of the identity (spp, seed, channels).
        """
        spec = self.registry.renderers[renderer]
        return make_key(
            what=what,
            scene=scene.content_hash(),
            renderer=spec.name,
            version=spec.version,
            settings=self.renderer(renderer).settings(),
            frame=frame_index,
            resolution=self.resolution(scene),
            **extra,
        )

    # ----------------------------------------------------------------- frames
    def frame(self, scene, renderer: str, frame_index: int, *, spp: int, seed: int, channels,
              render: Callable | None = None) -> Frame:
        """The noisy frame, from the cache or rendered (and stored); validated.

        Parameters
        ----------
        scene : Scene or str
        renderer : str
        frame_index : int
        spp, seed : int
        channels : iterable of str
            Channels to render besides ``color``.
        render : callable, optional
            ``render(scene, frame_index, *, spp, seed, channels, resolution) -> Frame``: renders a
            missing frame elsewhere (an executor); by default this process's renderer does.
        """
        scene = self.scene(scene) if isinstance(scene, str) else scene
        channels = frozenset(channels)
        key = self.key("frame", scene, renderer, frame_index, spp=spp, seed=seed, channels=sorted(channels))
        stored = self.cache.load("frames", key)
        if stored is not None:
            return Frame.from_arrays(stored, owner=f"cached frame of renderer {renderer!r}")
        draw = render if render is not None else self.renderer(renderer).render
        frame = draw(scene, frame_index, spp=spp, seed=seed, channels=channels, resolution=self.resolution(scene))
        if not isinstance(frame, Frame):
            raise ChannelError(
                f"renderer {renderer!r}: render() returned {type(frame).__name__}, expected harness.Frame"
            )
        frame = Frame(frame.arrays(), frame.meta, owner=f"renderer {renderer!r}")
        self.cache.store("frames", key, frame.to_arrays())
        return frame

    # ----------------------------------------------------------------- references
    def reference(
        self,
        scene,
        renderer: str,
        frame_index: int,
        *,
        spp: int,
        chunk: int = DEFAULT_CHUNK,
        progress: Callable[[int], None] | None = None,
        map_chunks: Callable | None = None,
    ) -> np.ndarray:
        """Load or render the converged reference of ``frame_index`` at ``spp`` samples per pixel.

        A renderer that declares ``chunked`` is run ``chunk`` samples at a time; the running
        float64 sum is stored after every chunk, so an interrupted render resumes where it
        stopped, and chunks are added in sample order, so the result is the same bit for bit
        however it was chunked or where the chunks ran. A renderer that is not chunked, or an
        analytic reference (``spp == 0``, allowed where the renderer's ``reference_spp`` is 0),
        is rendered by one ``reference()`` call.

        Parameters
        ----------
        scene : Scene or str
        renderer : str
        frame_index : int
        spp : int
            Samples per pixel (>= 1, or 0 for an analytic reference).
        chunk : int
            Samples per checkpoint (>= 1).
        progress : callable, optional
            Called with the number of samples just added (or found stored).
        map_chunks : callable, optional
            ``map_chunks(ranges) -> iterable of float64 sums in the same order``: renders the
            remaining sample ranges elsewhere (an executor); by default they run here.

        Returns
        -------
        ndarray (H, W, 3) float32
        """
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
        spec = self.registry.get("renderer", renderer)
        low = 0 if spec.reference_spp == 0 else 1
        if isinstance(spp, bool) or not isinstance(spp, int) or spp < low:
            raise ValueError(f"reference spp of renderer {renderer!r} must be an integer >= {low}, got {spp!r}")
        scene = self.scene(scene) if isinstance(scene, str) else scene
        analytic = spp == 0 or not spec.chunked
        key = self.key("reference", scene, renderer, frame_index, spp=spp, seed=REFERENCE_SEED)
        stored = self.cache.load("references", key)
        if stored is not None and _valid_image(stored.get("reference"), self.resolution(scene)):
            if progress is not None:
                progress(spp)
            return stored["reference"]
        if analytic:
            ref = self.renderer(renderer).reference(
                scene, frame_index, spp=spp, seed=REFERENCE_SEED, resolution=self.resolution(scene)
            )
            ref = np.ascontiguousarray(ref, np.float32)
            if progress is not None:
                progress(spp)
        else:
            ref = self._chunked_reference(scene, renderer, frame_index, spp, chunk, key, progress, map_chunks)
        self.cache.store("references", key, {"reference": ref})
        return ref

    def chunk_ranges(self, spp: int, chunk: int, done: int = 0) -> list[tuple[int, int]]:
        """The (first sample, count) ranges of a reference after ``done`` samples."""
        return [(first, min(chunk, spp - first)) for first in range(done, spp, chunk)]

    def accumulate(self, scene, renderer: str, frame_index: int, first_sample: int, count: int) -> np.ndarray:
        """The float64 sum of one range of reference samples (what a chunk task computes)."""
        scene = self.scene(scene) if isinstance(scene, str) else scene
        total = self.renderer(renderer).accumulate(
            scene, frame_index, first_sample=first_sample, count=count, seed=REFERENCE_SEED,
            resolution=self.resolution(scene),
        )
        return np.asarray(total, np.float64)

    def _chunked_reference(self, scene, renderer, frame_index, spp, chunk, key, progress, map_chunks):
        w, h = self.resolution(scene)
        partial = self.cache.load("partial", key)
        total, done = np.zeros((h, w, 3), np.float64), 0
        if partial is not None:
            stored_done = int(np.asarray(partial.get("done", -1)))
            if 0 < stored_done < spp and _valid_image(partial.get("sum"), (w, h), np.float64):
                total, done = partial["sum"], stored_done
            else:
                self.cache.discard("partial", key)
                warnings.warn(f"reference checkpoint {self.cache.path('partial', key)} is invalid "
                              f"({stored_done} of {spp} samples); rendering the reference again", stacklevel=2)
        if progress is not None and done:
            progress(done)
        ranges = self.chunk_ranges(spp, chunk, done)
        if map_chunks is None:
            sums = (self.accumulate(scene, renderer, frame_index, first, count) for first, count in ranges)
        else:
            sums = map_chunks(ranges)
        for (first, count), part in zip(ranges, sums):
            total = total + part
            done = first + count
            if done < spp:
                self.cache.store("partial", key, {"sum": total, "done": np.asarray(done)})
            if progress is not None:
                progress(count)
        self.cache.discard("partial", key)
        return (total / spp).astype(np.float32)


def _valid_image(array, resolution, dtype=np.float32) -> bool:
    w, h = resolution
    return isinstance(array, np.ndarray) and array.shape == (h, w, 3) and array.dtype == dtype


#: environment variable naming a folder of scene folders: the ``real`` tier of a default run
SCENES_ENV = "DENOISE_SCENES"


def default_scene_root() -> Path | None:
    """Where the ``real`` tier's scene folders are when the user names none.

    ``$DENOISE_SCENES`` where set (it must then be a folder), else ``../shared/scenes`` relative to
    the working directory or to the project root (the third-party scenes kept beside a checkout),
    else None.

    Raises
    ------
    FileNotFoundError
        ``$DENOISE_SCENES`` names no folder.
    """
    named = os.environ.get(SCENES_ENV, "").strip()
    if named:
        root = Path(named).expanduser()
        if not root.is_dir():
            raise FileNotFoundError(f"${SCENES_ENV} is {named!r}, which is not a folder")
        return root
    project = Path(__file__).resolve().parents[1]
    for base in (Path.cwd(), project):
        root = base.parent / "shared" / "scenes"
        if root.is_dir():
            return root
    return None


def folders_of_root(registry, root) -> tuple[list, list[str]]:
    """The scenes in the sub-folders of ``root`` that a plugin opens, in name order, and one line per
    sub-folder that none opens (why)."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"scene root {root} is not a folder")
    opened, skipped = [], []
    for folder in sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")):
        try:
            opened.append((folder, registry.open_scene(folder)))
        except ValueError as exc:
            skipped.append(f"{folder.name}: {exc}")
    return opened, skipped


def scene_selection(registry, store: RenderStore, scenes=None, scene_dirs=(), tasks=None, *, scene_roots=(),
                    real_resolution=None, notes: list | None = None) -> list:
    """Scene specs of ``scenes`` (default: the suite scenes of the tasks) plus folders opened as scenes.

    Folders (``scene_dirs``, and every sub-folder of each of ``scene_roots`` that a plugin opens)
    are opened through the plugins' ``open_scene`` hook, added to ``store`` and join the ``real``
    tier (unless the scene declares another in ``params["tier"]``). The suite is the default of
    ``scenes`` unless ``scene_dirs`` are named: a scene root's folders join the suite (the two
    tiers of a default run), a ``--scene-dir`` run scores its folders alone.

    Parameters
    ----------
    registry : harness.Registry
    store : RenderStore
    scenes : list of str, optional
    scene_dirs : list of path
    tasks : list of str, optional
    scene_roots : list of path
        Folders of scene folders (``--scene-root``, ``$DENOISE_SCENES``).
    real_resolution : (width, height), optional
        Resolution of the folder scenes that can be rendered at any size (not captures), where the
        store has no resolution override of its own (a profile's size of the real tier).
    notes : list, optional
        Receives one line per sub-folder of a root that no plugin opens.
    """
    from harness.specs import TASKS, SceneSpec

    tasks = set(tasks or TASKS)
    if scenes is None and not scene_dirs:
        specs = [s for _, s in sorted(registry.scenes.items()) if s.suite and s.tasks & tasks]
    else:
        specs = [registry.get("scene", n) for n in (scenes or [])]
    opened = [(Path(folder), registry.open_scene(folder)) for folder in scene_dirs]
    for root in scene_roots:
        found, skipped = folders_of_root(registry, root)
        opened += found
        if notes is not None:
            notes += [f"scene root {root}: skipped {line}" for line in skipped]
    for folder, scene in opened:
        if real_resolution is not None and scene.kind != "captured":
            scene = dataclasses.replace(scene, resolution=tuple(real_resolution))
        store.add_scene(scene, path=folder)
        specs.append(
            SceneSpec(
                name=scene.name,
                version="folder",
                factory=lambda s=scene: s,
                tags=scene.tags,
                frames=scene.frame_count,
                resolution=scene.resolution,
                kind=scene.kind,
                suite=False,
                tasks=scene.params.get("tasks") or {"denoise"},
                channels=scene.channels,
                tier=scene.params.get("tier") or "real",
            )
        )
    if not specs:
        raise ValueError("no scenes selected")
    names = [s.name for s in specs]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"scene name(s) {dupes} selected twice")
    return specs


__all__ = ["DEFAULT_CHUNK", "REFERENCE_SEED", "SCENES_ENV", "RenderStore", "default_scene_root", "folders_of_root",
           "scene_selection"]

