"""Anti-aliasing benchmark: quality on the AA scenes, the network's cost by depth, comparison pictures.

Calls the ``raster`` renderer, the AA filters and the harness's metric plugins (``ssim``,
``psnr``, ``flip``, ``temporal_error``) directly, in one process::

    python benchmarks/antialias.py quality  [--reference-spp 64] [--out FILE.json]
    python benchmarks/antialias.py depth    [--resolution 1280x720] [--layers 1,2,4,6]
    python benchmarks/antialias.py pictures [--scene aa-fence] [--frame 20] [--out-dir docs/images]

The AA filters' time per frame is ``denoise-bench bench noaa,fxaa,taa,aa_rnn --task antialias
--scene aa-fence --peers '' --no-error --rounds 5 --resolution 1280x720,1920x1080``.

``quality`` renders every scene of the ``antialias`` task (jittered input, SSAA references;
renders are kept in ``datasets/cache/antialias/``), runs each filter configuration over each whole
sequence from a camera cut, and prints per-scene and mean scores as Markdown tables, with a
ghosting measure: the error in the pixels that showed a moving object during the last 4 frames
but show something else now (where a trail would be). ``depth`` times the network's step at
each depth (random weights: the cost does not depend on their values), the depths taking turns
call by call (:func:`harness.timer.alternate`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from common import ROOT, alternate, integer, integers, parser, resolution, run, spread, timed_call

from harness import encode_srgb, load_plugins, write_png

CACHE = ROOT / "datasets" / "cache" / "antialias"
#: (label, filter, parameters) of every configuration compared
CONFIGS = [
    ("noaa", "noaa", {}),
    ("fxaa", "fxaa", {}),
    ("taa", "taa", {}),
    ("taa, no clipping", "taa", {"clipping": "none"}),
    ("taa, min/max box", "taa", {"clipping": "minmax"}),
    ("taa, no reconstruction", "taa", {"reconstruct": False}),
    ("aa_rnn", "aa_rnn", {}),
]
TRAIL_FRAMES = 4


def _configs(registry, only=None):
    configs = [c for c in CONFIGS if c[1] in registry.filters]
    if only:
        configs = [c for c in configs if c[0] in only]
    return configs


#: the G-buffer rendered (and cached) with every input: what the AA filters may read
GBUFFER = {"albedo", "normal", "depth", "object_id", "motion"}


def render_scene(registry, name: str, channels: set, spp: int, resolution=None):
    """Jittered frames and SSAA references of a whole scene (cached as .npz per scene and setting)."""
    from harness import Frame, FrameMeta

    spec = registry.get("scene", name)
    scene = spec.factory()
    w, h = resolution or scene.resolution
    raster_spec = registry.get("renderer", "raster")
    path = CACHE / f"{name}-{scene.content_hash()[:12]}-raster{raster_spec.version}-{w}x{h}-spp{spp}.npz"
    channels = sorted(channels)
    if path.is_file():
        data = np.load(path)
        frames = []
        for t in range(scene.frame_count):
            arrays = {c: data[f"{c}_{t}"] for c in ["color"] + channels}
            frames.append(Frame(arrays, FrameMeta(index=t, scene=name, jitter=tuple(data[f"jitter_{t}"]),
                                                  camera_cut=t == 0)))
        return scene, frames, [data[f"ref_{t}"] for t in range(scene.frame_count)]
    raster = raster_spec.factory(jitter=True)
    frames, refs = [], []
    for t in range(scene.frame_count):
        frames.append(raster.render(scene, t, channels=set(channels), resolution=(w, h)))
        refs.append(raster.reference(scene, t, spp=spp, resolution=(w, h)))
    CACHE.mkdir(parents=True, exist_ok=True)
    store = {}
    for t, (f, r) in enumerate(zip(frames, refs)):
        store.update({f"{c}_{t}": f[c] for c in ["color"] + channels})
        store[f"jitter_{t}"] = np.asarray(f.meta.jitter)
        store[f"ref_{t}"] = r
    np.savez_compressed(path, **store)
    return scene, frames, refs


def run_filter(registry, name: str, params: dict, frames) -> list[np.ndarray]:
    f = registry.get("filter", name).factory(backend="cpu", **params)
    f.reset()
    return [np.array(f(frame), copy=True) for frame in frames]


def trail_masks(scene, frames) -> list[np.ndarray]:
    """Per frame: pixels that showed a moving object in one of the last frames and do not now."""
    moving = [k for k, obj in enumerate(scene.objects) if obj.transforms is not None]
    return moving_trails(moving, [f["object_id"] for f in frames])


def moving_trails(moving, object_ids) -> list[np.ndarray]:
    """:func:`trail_masks` from the ids of the moving objects and each frame's ``object_id``."""
    on = [np.isin(ids, moving) for ids in object_ids]
    masks = []
    for t in range(len(on)):
        was = np.zeros_like(on[t])
        for k in range(1, TRAIL_FRAMES + 1):
            if t - k >= 0:
                was |= on[t - k]
        masks.append(was & ~on[t])
    return masks


def quality(args) -> dict:
    registry = load_plugins()
    configs = _configs(registry, args.filters)
    metrics = {m: registry.get("metric", m).factory() for m in ("ssim", "psnr", "flip", "temporal_error")}
    scenes = sorted(n for n, s in registry.scenes.items() if "antialias" in s.tasks and s.suite)
    results = {}
    for name in scenes:
        (scene, frames, refs), ms, _ = timed_call(lambda n=name: render_scene(registry, n, GBUFFER, args.reference_spp))
        masks = trail_masks(scene, frames)
        print(f"{name}: {len(frames)} frames {frames[0].width}x{frames[0].height}, rendered/read in "
              f"{ms / 1e3:.0f} s", flush=True)
        results[name] = {}
        for label, fname, params in configs:
            outs = run_filter(registry, fname, params, frames)
            row = {m: float(np.mean([metrics[m](o, r) for o, r in zip(outs, refs)])) for m in ("ssim", "psnr", "flip")}
            row["ssim_per_frame"] = [float(metrics["ssim"](o, r)) for o, r in zip(outs, refs)]
            row["temporal_error"] = float(metrics["temporal_error"](outs, refs))
            ghost = [np.abs(encode_srgb(o) - encode_srgb(r))[m].mean() for o, r, m in zip(outs, refs, masks)
                     if m.sum() >= 4]
            row["ghost"] = float(np.mean(ghost)) if ghost else float("nan")
            results[name][label] = row
            print(f"  {label:18s} SSIM {row['ssim']:.4f}  PSNR {row['psnr']:.2f}  FLIP {row['flip']:.4f}  "
                  f"temporal {row['temporal_error']:.4f}  ghost {row['ghost']:.4f}", flush=True)
    _quality_tables(results, [c[0] for c in configs], args.reference_spp)
    return {"reference_spp": args.reference_spp, "scenes": results, "machine": _machine()}


def _quality_tables(results, labels, spp) -> None:
    scenes = list(results)
    print(f"\nSSIM against the {int(np.sqrt(spp))}x{int(np.sqrt(spp))} SSAA reference (mean over frames)\n")
    print("| filter | " + " | ".join(scenes) + " | mean |")
    print("|---|" + "---|" * (len(scenes) + 1))
    for label in labels:
        values = [results[s][label]["ssim"] for s in scenes]
        print(f"| {label} | " + " | ".join(f"{v:.4f}" for v in values) + f" | **{np.mean(values):.4f}** |")
    print("\nMeans over the scenes: PSNR (dB, linear), FLIP (LDR), temporal_error, "
          "ghost (sRGB abs. error in the trail)\n")
    print("| filter | PSNR | FLIP | temporal_error | ghost |")
    print("|---|---|---|---|---|")
    for label in labels:
        rows = [results[s][label] for s in scenes]
        mean = {k: np.nanmean([r[k] for r in rows]) for k in ("psnr", "flip", "temporal_error", "ghost")}
        print(f"| {label} | {mean['psnr']:.2f} | {mean['flip']:.4f} | {mean['temporal_error']:.4f} | "
              f"{mean['ghost']:.4f} |")


def depth(args) -> dict:
    """Per-frame time of the ``aa_rnn`` step against its depth, in one process, depths alternating.

    The step's cost does not depend on the weights' values, so each depth runs with random (He)
    weights: this times the depths that have no shipped weights as well.
    """
    import numba
    import torch

    from plugins.filters.aa_rnn.network import AARNN, prepare

    w, h = args.resolution
    torch.manual_seed(0)
    torch.set_num_threads(numba.get_num_threads())
    rng = np.random.default_rng(0)
    depth_map = rng.uniform(1.0, 10.0, (1, 1, h, w)).astype(np.float32)
    normal = rng.normal(size=(1, 3, h, w)).astype(np.float32)
    with torch.inference_mode():
        inputs = prepare(torch.from_numpy(rng.exponential(0.5, (1, 3, h, w)).astype(np.float32)),
                         torch.from_numpy(normal), torch.from_numpy(depth_map),
                         torch.from_numpy(rng.normal(0.0, 1.0, (1, 2, h, w)).astype(np.float32)),
                         torch.tensor([[0.25, -0.25]]))
    models = {}
    for layers in args.layers:
        model = AARNN(layers).eval().to(memory_format=torch.channels_last)
        model.memory_format = torch.channels_last
        models[layers] = model
    state = {layers: None for layers in models}

    def step(layers):
        state[layers] = models[layers].step(inputs, state[layers])

    with torch.inference_mode():  # the first step (allocation, warm-up) is not counted
        result = alternate({layers: (lambda k=layers: step(k)) for layers in models}, args.frames - 1)
    table = {layers: {"median_ms": float(np.median(ms)), "min_ms": float(np.min(ms)), "max_ms": float(np.max(ms)),
                      "cpu_ms": float(np.median(result.cpu_ms[layers]))} for layers, ms in result.ms.items()}
    print(f"\naa_rnn step at {w}x{h}, {args.frames - 1} timed frames per depth (alternating), "
          f"{torch.get_num_threads()} threads\n")
    print("| hidden layers | ms median [min-max] | CPU ms median [min-max] |")
    print("|---|---|---|")
    for layers in models:
        print(f"| {layers} | {spread(result.ms[layers])} | {spread(result.cpu_ms[layers])} |")
    return {"resolution": f"{w}x{h}", "threads": torch.get_num_threads(), "machine": _machine(),
            "layers": {str(k): v for k, v in table.items()}}


def pictures(args) -> dict:
    """Aliased, TAA, network and SSAA side by side, with 4x zooms of an edge and a texture crop."""
    registry = load_plugins()
    configs = [c for c in _configs(registry) if c[0] in ("noaa", "taa", args.network)]
    scene, frames, refs = render_scene(registry, args.scene, GBUFFER, args.reference_spp)
    t = args.frame
    panels = [run_filter(registry, fname, params, frames[:t + 1])[t] for _, fname, params in configs] + [refs[t]]
    rows = [np.concatenate(panels, axis=1)]
    for box in (args.edge, args.texture):
        y, x, size = (int(v) for v in box.split(","))
        zooms = [np.repeat(np.repeat(p[y:y + size, x:x + size], args.zoom, 0), args.zoom, 1) for p in panels]
        strip = np.concatenate(zooms, axis=1)
        pad = rows[0].shape[1] - strip.shape[1]
        rows.append(np.pad(strip, ((0, 0), (0, max(pad, 0)), (0, 0)))[:, :rows[0].shape[1]])
    image = np.concatenate(rows, axis=0)
    path = Path(args.out_dir) / f"aa_compare_{args.scene}.png"
    write_png(path, image)
    print(path)
    return {"picture": str(path.relative_to(ROOT) if path.is_absolute() else path), "panels":
            [c[0] for c in configs] + ["SSAA"], "frame": t, "edge": args.edge, "texture": args.texture}


def _machine() -> dict:
    from harness.bench import bench_environment

    return bench_environment()


def main(argv=None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    q = sub.add_parser("quality")
    q.add_argument("--reference-spp", type=integer(1), default=64)
    q.add_argument("--filters", type=lambda s: s.split(";"), default=None, help="CONFIGS labels, ;-separated")
    q.add_argument("--out", default=None)
    d = sub.add_parser("depth")
    d.add_argument("--resolution", type=resolution, default=(1280, 720))
    d.add_argument("--layers", type=integers(1), default=[1, 2, 4, 6])
    d.add_argument("--frames", type=integer(2), default=8)
    d.add_argument("--out", default=None)
    p = sub.add_parser("pictures")
    p.add_argument("--scene", default="aa-fence")
    p.add_argument("--frame", type=integer(0), default=20)
    p.add_argument("--network", default="aa_rnn")
    p.add_argument("--reference-spp", type=integer(1), default=64)
    p.add_argument("--edge", default="60,150,40", help="y,x,size of the edge crop")
    p.add_argument("--texture", default="20,60,40", help="y,x,size of the texture crop")
    p.add_argument("--zoom", type=integer(1), default=4)
    p.add_argument("--out-dir", default=str(ROOT / "docs" / "images"))
    p.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    result = {"quality": quality, "depth": depth, "pictures": pictures}[args.command](args)
    if getattr(args, "out", None):
        Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    run(main)
