"""SBF quality at equal total samples: noisy input, EAW, SBF fixed, SBF adaptive.

Every entry of a block sees the same total samples per pixel N: the noisy input and the
fixed-input filters get an N-spp frame; adaptive SBF starts from N/2 spp and spends N/2 more per
pixel through the renderer's sampler (``samples_used`` is read back and printed). Errors are
the registered ``rmse``, ``relmse`` and ``ssim`` metrics against the renderer's reference.

    python benchmarks/sbf_quality.py [--scenes synthetic-edges,cornell] [--spp 4,8] [--seeds 3]
"""

from __future__ import annotations

import pandas as pd
from common import integer, integers, names, parser, run, timed_call

from harness import CHANNELS, load_plugins

METRICS = ("rmse", "relmse", "ssim")


def _renderer_for(registry, scene_spec):
    kind = scene_spec.kind
    name = "synthetic" if kind == "procedural" else "pathtracer"
    spec = registry.renderers[name]
    return name, spec, spec.factory()


def _score(registry, out, ref):
    return {m: float(registry.metrics[m].factory()(out, ref)) for m in METRICS if m in registry.metrics}


def study(scenes, spps, seeds):
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
                entries = {"noisy": (frame["color"], n * npix, 0.0)}  # (output, samples, ms of one call)
                if eaw is not None:
                    f = eaw.factory(backend="cpu", **dict(eaw.params))
                    f(frame)  # compile
                    out, ms, _ = timed_call(lambda f=f, x=frame: f(x))
                    entries["eaw"] = (out, n * npix, ms)
                f = sbf.factory(backend="cpu")
                f(frame)  # compile
                out, ms, _ = timed_call(lambda f=f, x=frame: f(x))
                entries["sbf fixed"] = (out, n * npix, ms)
                for passes in (1, 2):
                    half = n // 2
                    sampler = renderer.sampler(scene, 0, spp=half, seed=seed, channels=channels | {"spp"},
                                               resolution=res)
                    f = sbf.factory(backend="cpu", mode="adaptive", extra_spp=float(n - half), passes=passes)
                    out, ms, _ = timed_call(lambda f=f, s=sampler: f(s.frame, sampler=s))
                    entries[f"sbf adaptive {half}+{n - half} ({passes} pass)"] = (out, sampler.samples_used, ms)
                for name, (out, samples, ms) in entries.items():
                    rows.append({"scene": scene_name, "renderer": rname, "spp": n, "seed": seed, "entry": name,
                                 "spp_used": samples / npix, "ms": ms, **_score(registry, out, ref)})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("--scenes", type=names, default=["synthetic-edges", "cornell"])
    ap.add_argument("--spp", type=integers(2), default=[4, 8])
    ap.add_argument("--seeds", type=integer(1), default=3)
    args = ap.parse_args(argv)
    df = study(args.scenes, args.spp, args.seeds)
    cols = ["spp_used", "ms", *[m for m in METRICS if m in df]]
    table = df.groupby(["scene", "spp", "entry"], sort=False)[cols].mean()
    with pd.option_context("display.width", 200, "display.max_rows", 200):
        print(table.to_string(float_format=lambda v: f"{v:.4g}"))
    return 0


if __name__ == "__main__":
    run(main)
