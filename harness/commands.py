"""The work behind each ``denoise-bench`` sub-command (argument parsing is in :mod:`harness.cli`)."""

from __future__ import annotations

import json
import sys
from collections import defaultdict

import pandas as pd

from harness.cli import make_cache, scene_selection
from harness.plan import make_plan
from harness.results import (
    format_table,
    leaderboard,
    make_manifest,
    read_results,
    summary,
    to_markdown,
    write_manifest,
)
from harness.runner import Runner, RunOptions


def _grouped(pairs) -> dict:
    out = defaultdict(dict)
    for name, param, value in pairs:
        out[name][param] = value
    return dict(out)


def cmd_run(registry, args) -> int:
    """Plan, run, store and summarise a benchmark."""
    specs, opened = scene_selection(registry, args)
    filters = args.filters or sorted(registry.filters)
    metrics = args.metrics or sorted(registry.metrics)
    plan = make_plan(
        registry,
        specs,
        filters,
        metrics,
        renderer=args.renderer,
        backends=args.backend,
        spp=args.spp,
        seeds=args.seeds,
        frames=args.frames,
        resolution=args.resolution,
        params=_grouped(args.param),
        presets=dict(args.preset),
        reference_spp=args.reference_spp,
    )
    if args.out.exists() and not args.resume and (args.out / "jobs").exists():
        for stale in (args.out / "jobs").glob("*.parquet"):
            stale.unlink()
    cache = make_cache(args)
    options = RunOptions(
        repeats=args.repeats,
        nonfinite=args.nonfinite,
        resume=args.resume,
        progress=not args.quiet and sys.stderr.isatty(),
        pictures=args.pictures,
    )
    runner = Runner(registry, plan, cache, args.out, options, scenes=opened)
    print(
        f"denoise-bench run: {len(plan.jobs)} jobs on {len(specs)} scene(s), {len(plan.skipped)} skipped; "
        f"results in {args.out}",
        file=sys.stderr,
    )
    try:
        df = runner.run()
    finally:
        manifest = make_manifest(registry, plan, _options_dict(args), runner.scene_hashes, runner.reference_hashes)
        write_manifest(manifest, args.out / "manifest.json")
    if args.csv:
        df.to_csv(args.out / "results.csv", index=False)
    hits = sum(cache.hits.values())
    misses = sum(cache.misses.values())
    print(
        f"renders and references: {hits} reused from the cache, {misses} rendered"
        + (f"; {runner.reused_jobs} stored jobs reused (--resume)" if args.resume else "")
    )
    _print_summary(df, registry)
    errors = int((df.status == "error").sum())
    if errors:
        print(f"\n{errors} error row(s); see 'message' in {args.out / 'results.parquet'}")
    return 1 if (args.strict and errors) else 0


def _options_dict(args) -> dict:
    out = {}
    for k, v in vars(args).items():
        out[k] = str(v) if hasattr(v, "__fspath__") else v
    return json.loads(json.dumps(out, default=str))


def _print_summary(df: pd.DataFrame, registry) -> None:
    ok = df[df.status == "ok"]
    if not ok.empty:
        print("\nSummary (mean over frames; ms = median per-frame filter time):")
        print(format_table(summary(ok)))
        board = leaderboard(df, registry.metrics)
        if not board.empty:
            print("\nLeaderboard (mean rank over scenes and metrics, best first):")
            print(format_table(board))
    skipped = df[df.status == "skipped"]
    if not skipped.empty:
        print("\nSkipped:")
        reasons = skipped.groupby("message").apply(
            lambda g: ", ".join(sorted({f"{r.filter}/{r.backend} on {r.scene}" for r in g.itertuples()})),
            include_groups=False,
        )
        for reason, what in reasons.items():
            print(f"  {reason}: {what}")
    errors = df[df.status == "error"]
    if not errors.empty:
        print("\nErrors:")
        for r in errors.drop_duplicates("job_id").itertuples():
            print(f"  {r.filter}/{r.backend} on {r.scene} frame {r.frame}: {r.message}")


def cmd_show(registry, args) -> int:
    """Print the summary (or every row) and the leaderboard of a stored run."""
    df = read_results(args.dir)
    if args.all:
        print(format_table(df))
    else:
        _print_summary(df, registry)
    manifest = args.dir / "manifest.json"
    provenance = ""
    if manifest.exists():
        m = json.loads(manifest.read_text())
        provenance = (
            f"harness {m.get('harness_version')} at {m.get('git_commit') or 'unknown commit'}; "
            f"{m['machine'].get('cpu')} ({m['machine'].get('numba_threads')} threads); created {m.get('created')}"
        )
        print(f"\n{provenance}")
    if args.markdown is not None:
        ok = df[df.status == "ok"]
        board = leaderboard(df, registry.metrics)
        text = ["# Leaderboard", "", to_markdown(board), "## Per scene", "", to_markdown(summary(ok)), provenance, ""]
        args.markdown.write_text("\n".join(text))
        print(f"markdown written to {args.markdown}")
    return 0


def cmd_plugins(registry, args) -> int:
    """List plugins: kind, name, version, distribution, status and declarations."""
    records = [r.as_dict() for r in sorted(registry.records, key=lambda r: (r.kind, r.name))]
    if args.format == "json":
        print(json.dumps(records, indent=2, sort_keys=True))
        return 0
    widths = {
        k: max([len(k)] + [len(str(r[k])) for r in records])
        for k in ("kind", "name", "version", "distribution", "status")
    }
    header = "  ".join(k.ljust(w) for k, w in widths.items())
    print(header + "  declarations / error")
    for r in records:
        decl = r["declarations"]
        brief = ", ".join(f"{k}={_brief(v)}" for k, v in decl.items() if v not in ({}, [], "", None, False))
        print("  ".join(str(r[k]).ljust(w) for k, w in widths.items()) + "  " + (r["error"] or brief))
    return 0


def _brief(value) -> str:
    if isinstance(value, list):
        return "[" + ",".join(map(str, value)) + "]"
    if isinstance(value, dict):
        return "{" + ",".join(f"{k}:{v}" for k, v in value.items()) + "}"
    return str(value)


def cmd_render(registry, args) -> int:
    """Render references of every selected scene frame into the cache, in resumable chunks."""
    from tqdm.auto import tqdm

    specs, opened = scene_selection(registry, args)
    plan = make_plan(registry, specs, [], [], renderer=args.renderer, frames=args.frames, resolution=args.resolution)
    runner = Runner(registry, plan, make_cache(args), ".", RunOptions(progress=False), scenes=opened)
    for spec in specs:
        rname = args.renderer or _renderer_for(registry, spec)
        rspec = registry.get("renderer", rname)
        if not rspec.references:
            raise ValueError(f"renderer {rname!r} makes no references")
        spp = args.spp if args.spp is not None else rspec.reference_spp
        scene = runner.scene(spec.name)
        frames = spec.frames if args.frames is None else max(1, min(spec.frames, args.frames))
        with tqdm(
            total=frames * max(spp, 1),
            desc=f"{spec.name} ({rname}, {spp} spp)",
            unit="spp",
            disable=not sys.stderr.isatty(),
        ) as bar:
            for t in range(frames):
                runner.ensure_reference(rname, scene, t, spp, chunk=args.chunk, bar=bar)
        print(
            f"{spec.name}: {frames} reference frame(s) at {spp} spp, {runner.resolution(scene)[0]}x"
            f"{runner.resolution(scene)[1]}, in the cache"
        )
    return 0


def _renderer_for(registry, spec) -> str:
    from harness.plan import choose_renderer

    name = choose_renderer(registry, spec)
    if name is None:
        raise ValueError(f"no renderer for scene {spec.name!r} ({spec.kind})")
    return name


def cmd_bench(registry, args) -> int:
    """Time filters per frame at each resolution, with peers on the same frame."""
    from harness.bench import run_bench

    return run_bench(registry, args)


def cmd_train(registry, args) -> int:
    """Train a learned filter through its spec's ``trainer``."""
    spec = registry.get("filter", args.filter)
    if spec.trainer is None:
        raise ValueError(f"filter {spec.name!r} is not trainable")
    path = spec.trainer(seed=args.seed, output=args.output, quick=args.quick)
    print(f"{spec.name}: weights written to {path}")
    return 0
