"""SBF quality at equal total samples: noisy input, EAW, SBF fixed, SBF adaptive.

Every entry of a block sees the same total samples per pixel N: the noisy input and the
fixed-input filters get an N-spp frame; adaptive SBF starts from N/2 spp and spends N/2 more per
pixel through the renderer's sampler (``samples_used`` is read back and printed). Errors are
the registered ``rmse``, ``relmse`` and ``ssim`` metrics against the renderer's reference.

    python benchmarks/sbf_quality.py [--scenes synthetic-edges,cornell] [--spp 4,8] [--seeds 3]
"""

from __future__ import annotations

import argparse
import time

import pandas as pd

from harness import CHANNELS, load_plugins

METRICS = ("rmse", "relmse", "ssim")


def _renderer_for(registry, scene_spec):
    kind = scene_spec.kind
    name = "synthetic" if kind == "procedural" else "pathtracer"
    spec = registry.renderers[name]
    return name, spec, spec.factory()


def _score(registry, out, ref):
    return {m: float(registry.metrics[m].factory()(out, ref)) for m in METRICS if m in registry.metrics}


def run(scenes, spps, seeds):
    registry = load_plugins()
    sbf = registry.filters["sbf"]
    eaw = registry.filters.get("eaw")
    rows = []
    for scene_name in scenes:
        scene_spec = registry.scenes[scene_name]
        scene = scene_spec.factory()
        rname, rspec, renderer = _renderer_for(registry, scene_spec)
        res = scene_spec.resolution
        ref_spp = rspec.reference_spp
        ref = renderer.reference(scene, 0, spp=ref_spp, seed=10_000, resolution=res)
        channels = frozenset(CHANNELS) & rspec.provides
        for n in spps:
            for seed in range(seeds):
                frame = renderer.render(scene, 0, spp=n, seed=seed, channels=channels, resolution=res)
                npix = frame.height * frame.width
                entries = {"noisy": (frame["color"], n * npix, 0.0)}
                if eaw is not None:
                    f = eaw.factory(backend="cpu", **dict(eaw.params))
                    f(frame)  # compile
                    t0 = time.perf_counter()
                    out = f(frame)
                    entries["eaw"] = (out, n * npix, time.perf_counter() - t0)
                f = sbf.factory(backend="cpu")
                f(frame)  # compile
                t0 = time.perf_counter()
                out = f(frame)
                entries["sbf fixed"] = (out, n * npix, time.perf_counter() - t0)
                for passes in (1, 2):
                    half = n // 2
                    sampler = renderer.sampler(scene, 0, spp=half, seed=seed, channels=channels | {"spp"},
                                               resolution=res)
                    f = sbf.factory(backend="cpu", mode="adaptive", extra_spp=float(n - half), passes=passes)
                    t0 = time.perf_counter()
                    out = f(sampler.frame, sampler=sampler)
                    spent = time.perf_counter() - t0
                    entries[f"sbf adaptive {half}+{n - half} ({passes} pass)"] = (out, sampler.samples_used, spent)
                for name, (out, samples, seconds) in entries.items():
                    rows.append({"scene": scene_name, "renderer": rname, "spp": n, "seed": seed, "entry": name,
                                 "spp_used": samples / npix, "ms": seconds * 1e3, **_score(registry, out, ref)})
    return pd.DataFrame(rows)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="synthetic-edges,cornell")
    parser.add_argument("--spp", default="4,8")
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    df = run(args.scenes.split(","), [int(s) for s in args.spp.split(",")], args.seeds)
    cols = ["spp_used", "ms", *[m for m in METRICS if m in df]]
    table = df.groupby(["scene", "spp", "entry"], sort=False)[cols].mean()
    with pd.option_context("display.width", 200, "display.max_rows", 200):
        print(table.to_string(float_format=lambda v: f"{v:.4g}"))


if __name__ == "__main__":
    main()
