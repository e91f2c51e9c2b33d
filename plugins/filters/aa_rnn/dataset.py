"""The paper-scale training set of ``aa_rnn``, written to a folder by the harness's own renderer.

Each sequence is ``frames`` consecutive frames of one scene seen through a crop camera
(:mod:`.cropcam`: a ``size`` x ``size`` crop of a 360p-1080p frame, rolled by a random angle,
the eye moving and the view panning, or still), rendered by the ``raster`` renderer with jitter
(one shading sample per pixel at the Halton jitter, starting at a random phase of its 16-frame
cycle) with the G-buffer (albedo, normal, depth, object id, motion) and the 8x8 box SSAA
reference. The scenes:

* **procedural** (:mod:`.trainscenes`, one new random scene per sequence): thin bars and wires
  at pixel and sub-pixel width, grass blades, ground and walls textured with checkerboards,
  stripes and bit-blocks minified to moire, glossy plastic and metal spheres and tori (small
  bright highlights), 1-2 objects moving and turning (disocclusions);
* **Mitsuba** scenes that the ``raster`` renderer draws (registered scenes tagged ``mitsuba``
  whose files are present, e.g. ``../shared/scenes``): crops of their own camera's frame, the
  eye moving from the scene's camera position, with camera motion only (the scenes are static),
  scaled to a common exposure.

The benchmark scenes of the ``antialias`` task are never used (:func:`mitsuba_scenes` leaves out
every scene that serves that task, and the procedural generator shares no code with them).

**Split** 3:1:1 into training, validation and test **by scene**: a procedural sequence is its
own scene; all crops of one Mitsuba scene are one unit, and units are placed, largest first,
into the split furthest below its share, so no scene (hence no frame of it) is in two splits.

**Storage**: ``manifest.json`` (settings, the plan of every sequence: source, scene unit, split)
and one compressed ``seq_NNNNN.npz`` per sequence (float32 ``color``, ``albedo``, ``normal``,
``depth``, ``motion``, ``reference``, int32 ``object_id``, ``jitter`` (F, 2), and ``meta``, a JSON
string: source, seed, split, first frame index, crop camera, moving objects, CPU seconds).
Files are written whole (a temporary name, then renamed), so an interrupted run leaves only
complete sequences, and a rerun renders only the missing ones. Every sequence depends only on
the dataset seed and its index: the same settings give the same files whatever the number of
workers or the order they finish in.

**Parallel**: local worker processes (``executor="local"``, ``workers`` of them), a Dask cluster
(``executor="dask"``: a ``LocalCluster`` of ``workers`` processes, or the scheduler at
``scheduler``; its workers must see the folder), or the calling process (``"inline"``).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness import load_plugins

from .cropcam import crop_camera

log = logging.getLogger(__name__)

FORMAT = "aa_rnn-dataset"
FORMAT_VERSION = 1
SPLITS = ("train", "validation", "test")
SHARES = (0.6, 0.2, 0.2)
#: the G-buffer channels stored with every frame (with ``color``)
GBUFFER = ("albedo", "normal", "depth", "object_id", "motion")
#: arrays of a sequence file
ARRAYS = ("color",) + GBUFFER + ("jitter", "reference", "meta")
#: eye speed of moving procedural cameras, scene units (metres) per frame
PROCEDURAL_SPEED = (0.0, 0.15)
#: eye speed of Mitsuba crops, as a fraction of the median depth of the scene camera's view per frame
MITSUBA_SPEED = (0.0, 0.02)
#: largest pan rate, pixels per frame
PAN = 3.0
#: fraction of sequences with a still camera
STILL = 0.2
#: crops drawn per sequence at most, looking for one with :data:`MIN_EDGES` of edge pixels
CROP_TRIES = 6
MIN_EDGES = 0.05
#: a moving eye must keep its nearest surface at this fraction of the first frame's or more
CLEARANCE = 0.5
#: relative luminance step between neighbours that counts as an edge
EDGE_CONTRAST = 0.1
#: Mitsuba scenes are scaled to this mean luminance of their own camera's view (the raster
#: renderer's light units differ between scenes: the living room's mean is about 6)
EXPOSURE_MEAN = 0.35


@dataclass(frozen=True)
class DatasetConfig:
    """What a dataset folder holds (stored in its manifest; a rerun must ask for the same).

    Parameters
    ----------
    sequences : int
        Number of sequences (the paper: 1900).
    frames : int
        Frames per sequence (the paper: 7).
    size : int
        Side of the square crops, pixels.
    seed : int
        Seeds every random choice.
    reference_spp : int
        Samples of the SSAA reference (64: 8 x 8, what the benchmark scores against).
    mitsuba_share : float
        Fraction of the sequences cut from Mitsuba scenes (where any are present).
    mitsuba : tuple of str
        The Mitsuba scenes used (resolved by :func:`resolve`).
    """

    sequences: int = 1900
    frames: int = 7
    size: int = 64
    seed: int = 0
    reference_spp: int = 64
    mitsuba_share: float = 0.15
    mitsuba: tuple = ()

    def __post_init__(self):
        if self.sequences < 1 or self.frames < 2 or self.size < 8 or self.reference_spp < 1:
            raise ValueError(f"aa_rnn dataset: needs sequences >= 1, frames >= 2, size >= 8 and reference_spp >= 1, "
                             f"got {self.sequences}, {self.frames}, {self.size}, {self.reference_spp}")
        if not 0.0 <= self.mitsuba_share <= 1.0:
            raise ValueError(f"aa_rnn dataset: mitsuba_share must lie in [0, 1], got {self.mitsuba_share}")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["mitsuba"] = list(self.mitsuba)
        return d


def mitsuba_scenes(registry=None) -> list[str]:
    """Registered Mitsuba scenes (tag ``mitsuba``, kind ``mesh``) that load and serve no ``antialias``
    benchmark, in name order; absent files are left out with a log line."""
    registry = registry or load_plugins()
    names = []
    for name, spec in sorted(registry.scenes.items()):
        if "mitsuba" not in spec.tags or spec.kind != "mesh" or "antialias" in spec.tasks:
            continue
        try:
            _base_scene(name)
        except (FileNotFoundError, OSError, ValueError) as exc:
            log.info("aa_rnn dataset: Mitsuba scene %s left out (%s)", name, exc)
            continue
        names.append(name)
    return names


def resolve(config: DatasetConfig) -> DatasetConfig:
    """``config`` with :attr:`DatasetConfig.mitsuba` set to the scenes present (none if the share is 0)."""
    names = tuple(mitsuba_scenes()) if config.mitsuba_share > 0 else ()
    return dataclasses.replace(config, mitsuba=names)


def plan(config: DatasetConfig) -> list[dict]:
    """One entry per sequence: ``index``, ``source`` (``procedural`` or a Mitsuba scene), ``unit``
    (the scene it belongs to) and ``split``; deterministic in the config."""
    n = config.sequences
    m = int(round(config.mitsuba_share * n)) if config.mitsuba else 0
    sources = [config.mitsuba[k % len(config.mitsuba)] for k in range(m)] + ["procedural"] * (n - m)
    order = np.random.default_rng([config.seed, 1]).permutation(n)
    entries = [{"index": k, "source": sources[int(order[k])]} for k in range(n)]
    for e in entries:
        e["unit"] = f"procedural-{e['index']}" if e["source"] == "procedural" else e["source"]
    units: dict[str, list[dict]] = {}
    for e in entries:
        units.setdefault(e["unit"], []).append(e)
    targets = [share * n for share in SHARES]
    filled = [0, 0, 0]
    for _, members in sorted(units.items(), key=lambda kv: (-len(kv[1]), kv[1][0]["index"])):
        k = max(range(3), key=lambda s: (targets[s] - filled[s], -s))
        filled[k] += len(members)
        for e in members:
            e["split"] = SPLITS[k]
    return entries


def sequence_path(folder: Path, index: int) -> Path:
    return Path(folder) / f"seq_{index:05d}.npz"


# ---------------------------------------------------------------------------- one sequence

_BASES: dict = {}


def _base_scene(name: str):
    """A registered Mitsuba scene (textures read once), the median depth of its camera's view
    (distances of the crop cameras scale with it) and its exposure (:data:`EXPOSURE_MEAN` over
    the mean luminance of that view, 160 x 90), loaded once per process."""
    if name not in _BASES:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_plugins().get("scene", name).factory()
        materials = [dataclasses.replace(m, texture=m.texture_array()) if m.texture is not None else m
                     for m in scene.materials]
        scene = dataclasses.replace(scene, materials=materials)
        view = _worker_renderer().render(scene, 0, channels={"depth"}, resolution=(160, 90))
        depth = np.asarray(view["depth"], np.float64)
        distance = float(np.median(depth[np.isfinite(depth)])) if np.isfinite(depth).any() else 1.0
        mean = float(np.mean(np.asarray(view["color"], np.float64) @ np.array([0.2126, 0.7152, 0.0722])))
        _BASES[name] = (scene, distance, EXPOSURE_MEAN / mean if mean > 1e-6 else 1.0)
    return _BASES[name]


def _edge_fraction(frame) -> float:
    """Fraction of pixels whose right or lower neighbour shows another object or differs in
    luminance by more than :data:`EDGE_CONTRAST` of the brighter: where there is something to alias."""
    lum = np.asarray(frame["color"], np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    ids = np.asarray(frame["object_id"])

    def differ(a, b):
        return np.abs(a - b) > EDGE_CONTRAST * np.maximum(np.maximum(a, b), 1e-6)

    edge = np.zeros(lum.shape, bool)
    edge[:, 1:] |= differ(lum[:, 1:], lum[:, :-1]) | (ids[:, 1:] != ids[:, :-1])
    edge[1:] |= differ(lum[1:], lum[:-1]) | (ids[1:] != ids[:-1])
    return float(edge.mean())


def build_scene(config: DatasetConfig, entry: dict, renderer):
    """The scene of one sequence (camera path included) and the first frame index to render.

    The crop is drawn up to :data:`CROP_TRIES` times; a moving one whose eye comes too close to a
    surface (:func:`_keeps_clear`) is dropped; the first whose first frame has at least
    :data:`MIN_EDGES` edge pixels (:func:`_edge_fraction`) is kept, else the one with the most,
    else (every moving crop dropped) one more crop with a still eye.

    Returns
    -------
    (harness.Scene, int, dict)
        The scene (``first + frames`` frames long), ``first`` (the jitter phase: frame ``first``
        uses Halton point ``first + 1``) and what was drawn (crop camera, tries, exposure).
    """
    from .trainscenes import make_scene

    rng = np.random.default_rng([config.seed, 2, entry["index"]])
    first = int(rng.integers(0, 16))
    length = first + config.frames
    still = rng.random() < STILL
    pan = 0.0 if still else float(rng.uniform(0.0, PAN))
    exposure = 1.0
    if entry["source"] == "procedural":
        scene = make_scene(int(rng.integers(0, 1 << 30)), length, (config.size, config.size))
        speed = 0.0 if still else float(rng.uniform(*PROCEDURAL_SPEED))
        base = scene.camera
    else:
        scene, distance, exposure = _base_scene(entry["source"])
        speed = 0.0 if still else float(rng.uniform(*MITSUBA_SPEED)) * distance
        base = scene.camera
    name = f"aa_rnn-data-{config.seed}-{entry['index']}"
    resolution = (config.size, config.size)
    best = None
    for attempt in range(1, CROP_TRIES + 2):
        if attempt > CROP_TRIES:  # no moving crop kept clear of the geometry: a still eye cannot hit any
            speed = 0.0
        camera, drawn = crop_camera(rng, base, config.size, length, first, speed, pan)
        candidate = dataclasses.replace(scene, name=name, camera=camera, frame_count=length, resolution=resolution,
                                        tags=frozenset({"antialias", "training"}))
        probe = renderer.render(candidate, first, channels={"object_id", "depth"}, resolution=resolution)
        edges = _edge_fraction(probe)
        last = renderer.render(candidate, length - 1, channels={"depth"}, resolution=resolution) if speed > 0 else None
        if last is not None and not _keeps_clear(probe, last):
            continue
        if best is None or edges > best[2]:
            best = (candidate, drawn, edges)
        if edges >= MIN_EDGES or attempt > CROP_TRIES:
            break
    candidate, drawn, edges = best
    drawn.update(speed=speed, pan_pixels=pan, tries=attempt, edge_fraction=round(edges, 4), exposure=exposure)
    return candidate, first, drawn


def _keeps_clear(first, last) -> bool:
    """The nearest surface of the last frame is at least :data:`CLEARANCE` of the first frame's
    (a moving eye that reaches or passes through a surface fails)."""
    a, b = np.asarray(first["depth"]), np.asarray(last["depth"])
    if not np.isfinite(a).any():
        return True
    return bool(np.isfinite(b).any() and b[np.isfinite(b)].min() >= CLEARANCE * a[np.isfinite(a)].min())


def render_sequence(config: DatasetConfig, entry: dict, renderer=None) -> dict:
    """Render one planned sequence: the arrays of its file (``meta`` as a dict)."""
    t_cpu = time.process_time()
    if renderer is None:
        renderer = load_plugins().get("renderer", "raster").factory(jitter=True)
    scene, first, drawn = build_scene(config, entry, renderer)
    resolution = (config.size, config.size)
    frames = [renderer.render(scene, t, channels=set(GBUFFER), resolution=resolution)
              for t in range(first, first + config.frames)]
    refs = [renderer.reference(scene, t, spp=config.reference_spp, resolution=resolution)
            for t in range(first, first + config.frames)]
    arrays = {name: np.stack([np.asarray(f[name]) for f in frames]) for name in ("color",) + GBUFFER}
    arrays["object_id"] = arrays["object_id"].astype(np.int32)
    for name in ("color", "albedo", "normal", "depth", "motion"):
        arrays[name] = arrays[name].astype(np.float32)
    arrays["jitter"] = np.array([f.meta.jitter for f in frames], np.float32)
    arrays["reference"] = np.stack(refs).astype(np.float32)
    if drawn["exposure"] != 1.0:
        arrays["color"] *= np.float32(drawn["exposure"])
        arrays["reference"] *= np.float32(drawn["exposure"])
    arrays["meta"] = dict(entry, seed=config.seed, first_frame=first, camera=drawn,
                          moving_objects=[k for k, o in enumerate(scene.objects) if o.transforms is not None],
                          cpu_s=round(time.process_time() - t_cpu, 3))
    return arrays


def write_sequence(folder: Path, arrays: dict) -> Path:
    """Write a sequence's arrays compressed, under a temporary name renamed when complete."""
    path = sequence_path(folder, arrays["meta"]["index"])
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    store = dict(arrays, meta=np.array(json.dumps(arrays["meta"], sort_keys=True)))
    np.savez_compressed(tmp, **store)
    os.replace(tmp, path)
    return path


def read_meta(path: Path) -> dict | None:
    """The ``meta`` of a sequence file, or None if the file is missing, incomplete or unreadable."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if sorted(data.files) != sorted(ARRAYS):
                return None
            return json.loads(str(data["meta"]))
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, json.JSONDecodeError):
        return None


def read_sequence(path: Path) -> dict:
    """The arrays of a sequence file (``meta`` as a dict)."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: np.array(data[name]) for name in data.files}
    arrays["meta"] = json.loads(str(arrays["meta"]))
    return arrays


def _task(folder: str, config: dict, entry: dict) -> tuple[int, float]:
    """Render and write one sequence (run in a worker); returns its index and CPU seconds."""
    import numba

    numba.set_num_threads(1)
    config = DatasetConfig(**dict(config, mitsuba=tuple(config["mitsuba"])))
    arrays = render_sequence(config, entry, _worker_renderer())
    write_sequence(Path(folder), arrays)
    return entry["index"], arrays["meta"]["cpu_s"]


_RENDERER = []


def _worker_renderer():
    if not _RENDERER:
        _RENDERER.append(load_plugins().get("renderer", "raster").factory(jitter=True))
    return _RENDERER[0]


def _worker_init() -> None:
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass


# ---------------------------------------------------------------------------- the folder

def read_manifest(folder: Path) -> dict | None:
    path = Path(folder) / "manifest.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"aa_rnn dataset {folder}: unreadable manifest.json ({exc})") from None


def _write_manifest(folder: Path, manifest: dict) -> None:
    path = Path(folder) / "manifest.json"
    tmp = path.with_name(f".manifest.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(manifest, indent=1, sort_keys=True))
    os.replace(tmp, path)


def open_dataset(folder: Path, complete: bool = True) -> tuple[DatasetConfig, list[dict]]:
    """The config and plan of a dataset folder.

    Raises
    ------
    FileNotFoundError, ValueError
        No dataset there, or (``complete=True``) not complete: rerun its command to finish it.
    """
    manifest = read_manifest(folder)
    if manifest is None:
        raise FileNotFoundError(f"aa_rnn dataset {folder}: no manifest.json (make one with "
                                f"`denoise-bench train aa_rnn -o data={folder} -o stage=dataset`)")
    if manifest.get("format") != FORMAT or manifest.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"aa_rnn dataset {folder}: not an {FORMAT} folder of version {FORMAT_VERSION}")
    if complete and not manifest.get("complete"):
        raise ValueError(f"aa_rnn dataset {folder}: incomplete; rerun the command that made it to finish it")
    c = manifest["config"]
    return DatasetConfig(**dict(c, mitsuba=tuple(c["mitsuba"]))), manifest["plan"]


def generate(folder, config: DatasetConfig | None, workers: int = 1, executor: str = "local",
             scheduler: str | None = None) -> dict:
    """Render every missing sequence of the dataset into ``folder``; returns the manifest.

    Parameters
    ----------
    folder : path
        Created if needed. A folder holding a dataset with other settings is an error.
    config : DatasetConfig or None
        Resolved here (:func:`resolve`) unless the folder's manifest already names its Mitsuba
        scenes; None: the config of the dataset the folder holds.
    workers : int
        Worker processes (``local``, a ``dask`` ``LocalCluster``).
    executor : {"local", "dask", "inline"}
    scheduler : str, optional
        Address of a running Dask scheduler (``executor="dask"``).
    """
    folder = Path(folder)
    if executor not in ("local", "dask", "inline"):
        raise ValueError(f"aa_rnn dataset: executor must be local, dask or inline, got {executor!r}")
    if int(workers) < 1:
        raise ValueError(f"aa_rnn dataset: workers must be >= 1, got {workers}")
    folder.mkdir(parents=True, exist_ok=True)
    manifest = read_manifest(folder)
    if manifest is None and config is None:
        raise FileNotFoundError(f"aa_rnn dataset {folder}: no manifest.json, and no settings to make a dataset with")
    if manifest is not None:
        stored = dict(manifest["config"])
        asked = stored if config is None else dict(config.to_json(), mitsuba=stored.get("mitsuba"))
        if stored != asked or manifest.get("format_version") != FORMAT_VERSION:
            raise ValueError(f"aa_rnn dataset {folder}: holds a dataset made with {stored}, not {asked}; "
                             f"choose another folder")
        config = DatasetConfig(**dict(stored, mitsuba=tuple(stored["mitsuba"])))
    else:
        config = resolve(config)
        manifest = {"format": FORMAT, "format_version": FORMAT_VERSION, "config": config.to_json(),
                    "plan": plan(config), "complete": False}
        _write_manifest(folder, manifest)
    todo = [e for e in manifest["plan"] if read_meta(sequence_path(folder, e["index"])) is None]
    log.info("aa_rnn dataset %s: %d of %d sequences to render (%s, %d worker(s))", folder, len(todo),
             config.sequences, executor, workers)
    t_wall = time.perf_counter()
    for done, (index, cpu) in enumerate(_run(folder, config, todo, workers, executor, scheduler), 1):
        if done % 50 == 0 or done == len(todo):
            log.info("aa_rnn dataset: %d/%d rendered (last: sequence %d, %.1f CPU s), %.0f s", done, len(todo),
                     index, cpu, time.perf_counter() - t_wall)
    metas = [read_meta(sequence_path(folder, e["index"])) for e in manifest["plan"]]
    missing = [e["index"] for e, m in zip(manifest["plan"], metas) if m is None]
    if missing:
        raise RuntimeError(f"aa_rnn dataset {folder}: sequences {missing[:10]} were not written")
    manifest.update(complete=True, render_cpu_s=round(sum(m["cpu_s"] for m in metas), 1),
                    bytes=sum(sequence_path(folder, e["index"]).stat().st_size for e in manifest["plan"]),
                    splits={s: sum(e["split"] == s for e in manifest["plan"]) for s in SPLITS})
    _write_manifest(folder, manifest)
    return manifest


def _run(folder: Path, config: DatasetConfig, todo: list, workers: int, executor: str, scheduler):
    """Yield ``(index, cpu_s)`` as the sequences of ``todo`` are written."""
    args = (str(folder), config.to_json())
    if not todo:
        return
    if executor == "inline":
        _worker_init()
        for e in todo:
            yield _task(*args, e)
    elif executor == "local":
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=int(workers), mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_worker_init) as pool:
            futures = [pool.submit(_task, *args, e) for e in todo]
            for future in as_completed(futures):
                yield future.result()
    else:
        from dask.distributed import Client, LocalCluster, as_completed

        cluster = None
        if scheduler is None:
            cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                                   dashboard_address=None)
        client = Client(scheduler or cluster)
        try:
            client.run(_worker_init)
            futures = [client.submit(_task, *args, e, pure=False) for e in todo]
            for future in as_completed(futures):
                yield future.result()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


def load_split(folder, split: str, limit: int | None = None) -> tuple[list[np.ndarray], list[dict]]:
    """The prepared (F, 12, H, W) arrays (:func:`.data.to_planes`) and metas of one split, in index
    order; the first ``limit`` sequences only if given. Only those need to be rendered: a dataset
    still being made serves the sequences it already holds.

    Raises
    ------
    FileNotFoundError
        A sequence asked for is not (yet) in the folder.
    """
    from .data import to_planes

    _, entries = open_dataset(Path(folder), complete=False)
    chosen = [e for e in entries if e["split"] == split][:limit]
    planes, metas = [], []
    for e in chosen:
        path = sequence_path(folder, e["index"])
        if read_meta(path) is None:
            raise FileNotFoundError(f"aa_rnn dataset {folder}: sequence {e['index']} ({split}) is not rendered yet; "
                                    f"rerun the dataset's command to finish it")
        a = read_sequence(path)
        planes.append(to_planes(a["color"], a["normal"], a["depth"], a["motion"], a["jitter"], a["reference"]))
        metas.append(a["meta"])
    return planes, metas
