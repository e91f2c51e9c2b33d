"""What each ``denoise-bench`` sub-command does with its parsed arguments: call the library, print."""

from __future__ import annotations

import json
import sys
from collections import defaultdict

import pandas as pd

from harness.bench import DEFAULT_PEERS, bench_filters
from harness.cache import Cache
from harness.cli.stress import run_stress_command, show_stress
from harness.executors import DEFAULT_TIMEOUT_S, make_executor
from harness.executors.base import PluginOptions
from harness.lock import FolderLock, check_out_dir
from harness.manifest import read_manifest
from harness.plan import choose_renderer, make_plan
from harness.renders import RenderStore, scene_selection
from harness.results import format_table, leaderboard, read_results, summary, timing_setups, to_markdown
from harness.run import run_plan
from harness.specs import TASKS


def _grouped(pairs) -> dict:
    out = defaultdict(dict)
    for name, key, value in pairs:
        out[name][key] = value
    return dict(out)


def _cache(args) -> Cache:
    return Cache(args.cache_dir, enabled=not getattr(args, "no_cache", False))


def _cluster_options(args) -> dict:
    """``--scheduler``/``--workers`` as executor options, checked against ``--executor``."""
    if args.executor != "dask":
        if args.scheduler or args.workers:
            raise ValueError("--scheduler and --workers need --executor dask")
        return {}
    if args.scheduler and args.workers:
        raise ValueError("--workers sizes a local cluster; with --scheduler the cluster's own workers run")
    return {"scheduler": args.scheduler, "workers": args.workers}


def _executor(registry, args):
    plugins = PluginOptions(disable=list(args.disable))
    options = {"registry": registry, "plugins": plugins, "timeout": getattr(args, "timeout", DEFAULT_TIMEOUT_S)}
    executor = make_executor(args.executor, **options, **_cluster_options(args))
    if hasattr(executor, "banner"):
        print(executor.banner(), file=sys.stderr)
    return executor


def cmd_stress(registry, args) -> int:
    """Run filters through the stress battery, fuzz them, or replay a reproducer (:mod:`harness.cli.stress`)."""
    return run_stress_command(registry, args, lambda: _executor(registry, args))


def _progress(args) -> bool:
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def cmd_run(registry, args) -> int:
    """Plan, run, store and summarise a benchmark."""
    tasks = list(TASKS) if args.task == "all" else [args.task]
    _cluster_options(args)
    with FolderLock(check_out_dir(args.out)):
        return _run(registry, args, tasks)


def _run(registry, args, tasks) -> int:
    store = RenderStore(registry, _cache(args), resolution=args.resolution)
    specs = scene_selection(registry, store, args.scenes, args.scene_dir, tasks)
    filters = args.filters or sorted(n for n, s in registry.filters.items() if s.tasks & set(tasks))
    metrics = args.metrics or sorted(registry.metrics)
    plan = make_plan(
        registry, store, specs, filters, metrics, tasks=tasks, renderer=args.renderer, backends=args.backend,
        spp=args.spp, seeds=args.seeds, frames=args.frames, params=_grouped(args.param), presets=dict(args.preset),
        repeats=args.repeats, reference_spp=args.reference_spp, nonfinite=args.nonfinite,
    )
    print(f"denoise-bench run: {len(plan.jobs)} jobs on {len(specs)} scene(s), {len(plan.skipped)} skipped; "
          f"results in {args.out}", file=sys.stderr)
    with _executor(registry, args) as executor:
        outcome = run_plan(registry, plan, store, executor, args.out, resume=args.resume, pictures=args.pictures,
                           save_outputs=args.save_outputs, progress=_progress(args))
    df = outcome.table
    if args.csv:
        df.to_csv(args.out / "results.csv", index=False)
    hits, misses = sum(store.cache.hits.values()), sum(store.cache.misses.values())
    line = f"renders and references: {hits} reused from the cache, {misses} rendered"
    if args.resume:
        line += f"; {outcome.reused} stored jobs reused (--resume)"
        if outcome.removed:
            line += f", {outcome.removed} stored jobs of other settings removed"
    print(line)
    _print_summary(df, registry)
    errors = int(df[df.status == "error"].job_id.nunique())
    if errors:
        print(f"\n{errors} job(s) with errors; see 'message' in {args.out / 'results.parquet'}")
    return 1 if (args.strict and errors) else 0


def _print_summary(df: pd.DataFrame, registry) -> None:
    ok = df[df.status == "ok"]
    if not ok.empty:
        print("\nSummary (mean over frames; ms = median per-frame filter time):")
        print(format_table(summary(ok)))
        board = leaderboard(df, registry.metrics)
        for task, part in board.groupby("task", sort=True):
            print(f"\nLeaderboard, task {task} (mean rank over scenes and metrics, best first):")
            print(format_table(part.drop(columns="task")))
        setups = timing_setups(df)
        if len(setups) > 1:
            print(f"\nNote: rows were timed on {len(setups)} machine setups ({'; '.join(setups)}); compare ms_median "
                  "only between entries of the same setup (column timed_on)")
    skipped = df[df.status == "skipped"]
    if not skipped.empty:
        print("\nSkipped:")
        for reason, g in skipped.groupby("message", sort=True):
            what = ", ".join(sorted({f"{r.filter}/{r.backend} on {r.scene}" if r.scene else r.filter
                                     for r in g.itertuples()}))
            print(f"  {reason}: {what}")
    errors = df[df.status == "error"]
    if not errors.empty:
        print("\nErrors:")
        for r in errors.drop_duplicates("job_id").itertuples():
            print(f"  {r.filter}/{r.backend} on {r.scene} frame {r.frame}: {r.message}")


def cmd_show(registry, args) -> int:
    """Print the summary (or every row) and the leaderboard of a stored run."""
    if (read_manifest(args.dir) or {}).get("kind") == "stress":
        return show_stress(args)
    df = read_results(args.dir)
    if args.all:
        print(format_table(df))
    else:
        _print_summary(df, registry)
    m = read_manifest(args.dir)
    provenance = ""
    if m:
        commit = m.get("git_commit") or "unknown commit"
        if m.get("git_dirty"):
            commit += " (modified)"
        provenance = (f"harness {m.get('harness_version')} at {commit}; {m['machine'].get('cpu')} "
                      f"({m['machine'].get('numba_threads')} threads); created {m.get('created')}")
        print(f"\n{provenance}")
    if args.markdown is not None:
        board = leaderboard(df, registry.metrics)
        text = ["# Leaderboard", ""]
        for task, part in board.groupby("task", sort=True):
            text += [f"## Task {task}", "", to_markdown(part.drop(columns="task"))]
        text += ["## Per scene", "", to_markdown(summary(df[df.status == "ok"])), provenance, ""]
        args.markdown.write_text("\n".join(text))
        print(f"markdown written to {args.markdown}")
    return 0


def cmd_plugins(registry, args) -> int:
    """List plugins: kind, name, version, distribution, status and declarations."""
    records = [r.as_dict() for r in sorted(registry.records, key=lambda r: (r.kind, r.name))]
    if args.format == "json":
        print(json.dumps(records, indent=2, sort_keys=True, default=str))
        return 0
    widths = {k: max([len(k)] + [len(str(r[k])) for r in records])
              for k in ("kind", "name", "version", "distribution", "status")}
    print("  ".join(k.ljust(w) for k, w in widths.items()) + "  declarations / error")
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

    _cluster_options(args)
    store = RenderStore(registry, _cache(args), resolution=args.resolution)
    specs = scene_selection(registry, store, args.scenes, args.scene_dir, [args.task])
    work = [_what_to_render(registry, store, spec, args) for spec in specs]
    if args.executor == "dask":
        return _render_on_cluster(registry, args, store, work)
    for spec, rname, spp, frames in work:
        width, height = store.resolution_of(spec)
        with tqdm(total=frames * max(spp, 1), desc=f"{spec.name} ({rname}, {spp} spp)", unit="spp",
                  disable=not sys.stderr.isatty()) as bar:
            for t in range(frames):
                store.reference(spec.name, rname, t, spp=spp, chunk=args.chunk, progress=bar.update)
        print(f"{spec.name}: {frames} reference frame(s) at {spp} spp, {width}x{height}, in the cache")
    return 0


def cmd_export(registry, args) -> int:
    """Write every selected scene as a capture folder (multi-layer EXR frames, references, sidecar)."""
    from harness.export import export_scene

    store = RenderStore(registry, _cache(args), resolution=args.resolution)
    specs = scene_selection(registry, store, args.scenes, args.scene_dir, [args.task])
    for spec in specs:
        sidecar = export_scene(registry, store, spec, args.out / spec.name, task=args.task, renderer=args.renderer,
                               frames=args.frames, spp=args.spp, seed=args.seed, reference_spp=args.reference_spp,
                               half=args.half)
        print(f"{spec.name}: written to {sidecar.parent} (open it with --scene-dir {sidecar.parent})")
    return 0


def _what_to_render(registry, store, spec, args) -> tuple:
    """(scene spec, renderer, reference spp, frames) of one scene of ``denoise-bench render``."""
    rname = args.renderer or choose_renderer(registry, spec, args.task)
    if rname is None:
        raise ValueError(f"no renderer serves task {args.task!r} for scene {spec.name!r} ({spec.kind})")
    rspec = registry.get("renderer", rname)
    if not rspec.references:
        raise ValueError(f"renderer {rname!r} makes no references")
    spp = args.spp if args.spp is not None else rspec.reference_spp
    frames = spec.frames if args.frames is None else min(spec.frames, args.frames)
    return spec, rname, spp, frames


def _render_on_cluster(registry, args, store, work) -> int:
    """Every chunk of every reference as a task; one progress bar over all of them."""
    import threading

    from tqdm.auto import tqdm

    from harness.remote_renders import RemoteRenders

    lock = threading.Lock()
    total = sum(frames * max(spp, 1) for _, _, spp, frames in work)
    with _executor(registry, args) as executor, RemoteRenders(store, executor, chunk=args.chunk) as renders, \
            tqdm(total=total, desc=f"references ({args.chunk} spp per task)", unit="spp",
                 disable=not sys.stderr.isatty()) as bar:
        def tick(n: int) -> None:
            with lock:
                bar.update(n)

        requests = [(spec, rname, spp, frames, [renders.reference(spec.name, rname, t, spp=spp, progress=tick)
                                                for t in range(frames)]) for spec, rname, spp, frames in work]
        for spec, _, spp, frames, futures in requests:
            for future in futures:
                future.result()
            width, height = store.resolution_of(spec)
            print(f"{spec.name}: {frames} reference frame(s) at {spp} spp, {width}x{height}, in the cache")
    return 0


def cmd_bench(registry, args) -> int:
    """Time filters per frame at each resolution, with peers on the same frame."""
    import numba

    peers = args.peers if args.peers is not None else [p for p in DEFAULT_PEERS if p in registry.filters]
    store = RenderStore(registry, Cache(args.cache_dir))
    with _executor(registry, args) as executor:
        result = bench_filters(
            registry, store, executor, args.filters, peers=peers, scene=args.scene, renderer=args.renderer,
            task=args.task, resolutions=args.resolution, backend=args.backend, repeats=args.repeats,
            params=_grouped(args.param), presets=dict(args.preset),
        )
    print(f"scene {args.scene}, backend {args.backend}, {numba.get_num_threads()} threads, {args.executor} "
          f"executor, {args.repeats} timed calls per frame (x_vs_PEER = peer ms / filter ms)")
    print(format_table(result.table))
    if not result.stages.empty:
        print("\nPer-stage milliseconds (last timed call):")
        print(format_table(result.stages))
    table = result.table
    return 0 if not table.empty and table["status"].eq("ok").any() else 1


def cmd_train(registry, args) -> int:
    """Train a learned filter through its spec's ``trainer``."""
    spec = registry.get("filter", args.filter)
    if spec.trainer is None:
        raise ValueError(f"filter {spec.name!r} is not trainable")
    path = spec.trainer(seed=args.seed, output=args.output, quick=args.quick)
    print(f"{spec.name}: weights written to {path}")
    return 0
