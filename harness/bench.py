"""``denoise-bench bench``: per-frame filter time against peers measured in the same process.

Each resolution gets one rendered frame (two for temporal filters: the second is timed, with
history); every filter, the peers included, runs through the runner's timing protocol on that
same frame. The table shows median/min/max milliseconds, the compile/warm-up call, RMSE against
the reference, and each filter's time relative to every peer (peer ms / filter ms: above 1 means
faster than the peer).
"""

from __future__ import annotations

import json
import math
import tempfile

import pandas as pd

from harness.plan import make_plan
from harness.results import format_table
from harness.runner import Runner, RunOptions

DEFAULT_PEERS = ("opencv_jbf", "oidn")


def run_bench(registry, args) -> int:
    from harness.cli import _resolution, make_cache

    targets = list(args.filters)
    peers = args.peers if args.peers is not None else [p for p in DEFAULT_PEERS if p in registry.filters]
    peers = [p for p in peers if p not in targets]
    names = targets + peers
    specs = [registry.get("filter", n) for n in names]
    scene_spec = registry.get("scene", args.scene)
    frames = 2 if any(s.temporal for s in specs) else 1
    metrics = ["rmse"] if "rmse" in registry.metrics else []
    params, presets = {}, dict(args.preset)
    for name, key, value in args.param:
        params.setdefault(name, {})[key] = value
    rows = []
    stages = []
    for res_text in args.resolution:
        resolution = _resolution(res_text)
        plan = make_plan(
            registry,
            [scene_spec],
            names,
            metrics,
            renderer=args.renderer,
            backends=[args.backend],
            frames=frames,
            resolution=resolution,
            params=params,
            presets=presets,
        )
        with tempfile.TemporaryDirectory() as tmp:
            runner = Runner(registry, plan, make_cache(args), tmp, RunOptions(repeats=args.repeats, progress=False))
            df = runner.run()
        for job, reason in plan.skipped:
            rows.append({"filter": job.filter, "resolution": res_text, "status": f"skipped: {reason}"})
        for name in names:
            sub = df[(df["filter"] == name) & (df.status != "skipped")]
            if sub.empty:
                continue
            last = sub.iloc[-1]
            compile_ms = sub["compile_ms"].dropna()
            rows.append(
                {
                    "filter": name,
                    "resolution": res_text,
                    "ms_median": last.ms_median,
                    "ms_min": last.ms_min,
                    "ms_max": last.ms_max,
                    "compile_ms": compile_ms.iloc[0] if len(compile_ms) else math.nan,
                    "rmse": last.get("rmse", math.nan),
                    "status": last.status if last.status == "ok" else f"error: {last.message}",
                }
            )
            if last.stage_ms:
                stages.append({"filter": name, "resolution": res_text, **json.loads(last.stage_ms)})
    table = pd.DataFrame(rows)
    for peer in peers:
        if "ms_median" not in table:
            break
        peer_ms = table[table["filter"] == peer].set_index("resolution")["ms_median"]
        table[f"x_vs_{peer}"] = [
            peer_ms.get(r, math.nan) / ms if ms else math.nan for r, ms in zip(table["resolution"], table["ms_median"])
        ]
    import numba

    print(
        f"scene {scene_spec.name}, backend {args.backend}, {numba.get_num_threads()} threads, "
        f"{args.repeats} timed calls per frame (x_vs_PEER = peer ms / filter ms)"
    )
    print(format_table(table))
    if stages:
        print("\nPer-stage milliseconds (last timed call):")
        print(format_table(pd.DataFrame(stages)))
    return 0 if not table.empty and table["status"].eq("ok").any() else 1
