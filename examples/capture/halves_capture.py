"""Capture a built-in scene as two half-buffers, and score SBF and LBF with the variance they give.

The project's path tracer renders frame 0 of a built-in scene twice at ``spp / 2`` samples per
pixel with two seeds (``2 seed`` and ``2 seed + 1``): the two independent half-buffers of an
``spp``-sample colour. They are written as layers ``half_a`` and ``half_b`` of
``frames/0000.exr`` with the G-buffer (albedo, normal, depth, position, emission) and a
``capture.toml`` naming them in ``color_halves`` (no ``color``: the ``captured`` renderer serves
their mean, and the ``variance`` channel from them). The reference is the mean of 8 renders of
``reference_spp / 8`` samples (seeds 1000 to 1007), stored with its variance of the mean (their
spread / 8) for the metrics' bias correction. Usage::

    python examples/capture/halves_capture.py OUT_DIR --scene cornell --resolution 64x64 \\
        --spp 2,4,8 --seeds 1,2,3 --reference-spp 1024 --score

writes ``OUT_DIR/<scene>-<spp>spp-seed<seed>`` per setting; ``--score`` opens each with the
``captured`` renderer and prints, per filter, ``relmse`` and ``display_rmse`` (emitters and the
ring of pixels around them left out, as in ``denoise-bench run``) with the half-buffer
``variance`` and without it (the filters then estimate it from the image), and their means over
the seeds.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: layers of the two half-buffers in ``frames/0000.exr``
HALF_LAYERS = ("half_a", "half_b")
#: G-buffer channels written beside them (emission: to leave the emitters out of the scores)
GUIDES = ("albedo", "normal", "depth", "position", "emission")
#: renders averaged into a reference, and the seed of the first
REFERENCE_RENDERS = 8
REFERENCE_SEED = 1000
#: metrics printed (lower is better)
METRICS = ("relmse", "display_rmse")


def render_reference(registry, scene_name: str, resolution: tuple, spp: int) -> tuple:
    """Frame 0's reference (mean of :data:`REFERENCE_RENDERS` renders), its variance of the mean
    and its samples per pixel."""
    renderer = registry.get("renderer", "pathtracer").factory()
    scene = registry.get("scene", scene_name).factory()
    each = max(spp // REFERENCE_RENDERS, 1)
    renders = np.stack([
        renderer.reference(scene, 0, spp=each, seed=REFERENCE_SEED + k, resolution=resolution).astype(np.float64)
        for k in range(REFERENCE_RENDERS)
    ])
    mean = renders.mean(axis=0)
    variance = renders.var(axis=0, ddof=1) / REFERENCE_RENDERS
    return mean.astype(np.float32), variance.astype(np.float32), each * REFERENCE_RENDERS


def write_halves_capture(folder: Path, registry, scene_name: str, resolution: tuple, spp: int, seed: int,
                         reference: tuple) -> Path:
    """Render the two half-buffers of frame 0 and write the capture folder; returns its sidecar."""
    from harness import CHANNELS, write_channels

    if spp < 2 or spp % 2:
        raise ValueError(f"spp must be even and >= 2 (two halves of spp / 2 samples), got {spp}")
    renderer = registry.get("renderer", "pathtracer").factory()
    scene = registry.get("scene", scene_name).factory()
    halves = [renderer.render(scene, 0, spp=spp // 2, seed=2 * seed + k, channels=frozenset(CHANNELS),
                              resolution=resolution) for k in range(2)]
    planes = {}
    for layer, frame in zip(HALF_LAYERS, halves):
        planes.update({f"{layer}.{c}": frame["color"][..., i] for i, c in enumerate("RGB")})
    first = halves[0]
    for name in GUIDES:
        value = first[name]
        if value.ndim == 2:
            planes[f"{name}.Z"] = value
        else:
            planes.update({f"{name}.{c}": value[..., i] for i, c in enumerate("XYZ" if name in ("normal", "position")
                                                                              else "RGB")})
    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    (folder / "reference").mkdir(parents=True, exist_ok=True)
    write_channels(folder / "frames" / "0000.exr", planes)
    image, variance, reference_spp = reference
    write_channels(folder / "reference" / "0000.exr", {
        **{c: image[..., i] for i, c in enumerate("RGB")},
        **{f"variance.{c}": variance[..., i] for i, c in enumerate("RGB")},
    })
    sidecar = folder / "capture.toml"
    sidecar.write_text(
        f'name = "{scene_name}-halves"\n'
        f'description = "{scene_name} frame 0, two path-traced halves of {spp // 2} spp (seeds {2 * seed}, '
        f'{2 * seed + 1})"\n'
        'frames = 1\n'
        'file = "frames/{frame:04d}.exr"\n'
        f"spp = {spp}\n"
        "[channels]\n"
        f'color_halves = ["{HALF_LAYERS[0]}", "{HALF_LAYERS[1]}"]\n'
        + "".join(f'{name} = "{name}"\n' for name in GUIDES)
        + "[reference]\n"
        'file = "reference/{frame:04d}.exr"\n'
        'layer = ""\n'
        f"spp = {reference_spp}\n"
        'variance = "variance"\n'
    )
    return sidecar


def score(folder: Path, registry, filters=("sbf", "lbf")) -> dict:
    """``{(filter, "halves" | "spatial"): {metric: value}}`` for frame 0 of the capture in ``folder``.

    ``halves``: the filter gets the captured ``variance``; ``spatial``: the same frame without it.
    """
    from harness.jobs import emitter_mask

    scene = registry.open_scene(folder)
    renderer = registry.get("renderer", "captured").factory()
    spp = scene.params["capture"]["spp"]
    frame = renderer.render(scene, 0, spp=spp, channels=frozenset(scene.params["channels"]))
    reference = renderer.reference(scene, 0)
    reference_variance = renderer.reference_variance(scene, 0)
    mask = emitter_mask(frame)
    metrics = {m: registry.metrics[m].factory() for m in METRICS}
    out = {}
    for name in filters:
        spec = registry.filters[name]
        for variant, channels in (("halves", frame.channels), ("spatial", frame.channels - {"variance"})):
            filt = spec.factory(backend="cpu", **spec.params)
            filt.reset()
            image = filt(frame.subset((spec.requires | spec.optional) & channels), sampler=None)
            out[(name, variant)] = {
                m: float(metric(image, reference, reference_variance=reference_variance, mask=mask))
                for m, metric in metrics.items()
            }
    out[("input", "-")] = {
        m: float(metric(frame["color"], reference, reference_variance=reference_variance, mask=mask))
        for m, metric in metrics.items()
    }
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--scene", default="cornell", help="a built-in scene (default cornell)")
    parser.add_argument("--resolution", default="64x64", help="WxH (default 64x64)")
    parser.add_argument("--spp", default="4", help="samples per pixel of the colour, even, comma-separated")
    parser.add_argument("--seeds", default="1", help="comma-separated")
    parser.add_argument("--reference-spp", type=int, default=1024)
    parser.add_argument("--score", action="store_true", help="score SBF and LBF with and without the variance")
    args = parser.parse_args(argv)

    from harness import load_plugins

    registry = load_plugins()
    width, height = (int(v) for v in args.resolution.lower().split("x"))
    reference = render_reference(registry, args.scene, (width, height), args.reference_spp)
    for spp in (int(v) for v in args.spp.split(",")):
        table: dict = {}
        for seed in (int(v) for v in args.seeds.split(",")):
            folder = args.out_dir / f"{args.scene}-{spp}spp-seed{seed}"
            write_halves_capture(folder, registry, args.scene, (width, height), spp, seed, reference)
            print(f"wrote {folder}")
            if args.score:
                for key, values in score(folder, registry).items():
                    table.setdefault(key, []).append(values)
        for (name, variant), rows in table.items():
            means = "  ".join(f"{m} {np.mean([r[m] for r in rows]):.5f}" for m in METRICS)
            seeds = " ".join(f"{r['relmse']:.4f}" for r in rows)
            print(f"{args.scene} {width}x{height} {spp} spp  {name:5s} {variant:7s}  {means}  "
                  f"(relmse per seed: {seeds})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
