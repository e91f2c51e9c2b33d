"""What each ``denoise-bench`` sub-command does with its parsed arguments: call the library, print."""

from __future__ import annotations

import inspect
import json
import sys
import time
from collections import defaultdict

import pandas as pd

from harness.bench import DEFAULT_PEERS, bench_filters
from harness.bench_rounds import bench_rounds
from harness.benchmark import run_benchmark
from harness.cache import Cache
from harness.cli.checks import (
    check_rank_by,
    check_run_options,
    markdown_file,
)
from harness.cli.stress import run_stress_command, show_stress
from harness.estimate import check_work, reference_work
from harness.executors import DEFAULT_TIMEOUT_S, make_executor
from harness.executors.base import PluginOptions
from harness.lock import output_folder
from harness.manifest import read_manifest
from harness.numba_cache import CompileProgress, compile_notice, plan_units
from harness.pareto import (
    DEFAULT_BUDGETS,
    best_within,
    configuration_points,
    pareto_front,
    resolution_label,
    time_resolution,
)
from harness.plan import choose_renderer
from harness.profiles import PROFILES, get_profile
from harness.references import reference_record
from harness.render_cost import measure_render_cost, read_render_cost, write_render_cost
from harness.renders import SCENES_ENV, RenderStore, default_scene_root, scene_selection
from harness.report import write_report
from harness.results import (
    TIME_COLUMNS,
    board_table,
    format_table,
    leaderboard,
    rank_agreement,
    read_results,
    summary,
    tier_boards,
    timing_setups,
    to_markdown,
)
from harness.threads import max_threads


def _grouped(pairs) -> dict:
    out = defaultdict(dict)
    for name, key, value in pairs:
        out[name][key] = value
    return dict(out)


def _grid(items) -> dict:
    """``--grid`` values: filter -> {param: values}; a parameter given twice keeps its values in order."""
    out = defaultdict(dict)
    for name, key, values in items:
        out[name][key] = list(dict.fromkeys([*out[name].get(key, []), *values]))
    return dict(out)


def _cache(args) -> Cache:
    """The render cache of ``--cache-dir``/``--no-cache``, checked usable before any work."""
    return Cache(args.cache_dir, enabled=not getattr(args, "no_cache", False)).check()


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
    """Plan, run, store and summarise a benchmark (:func:`harness.benchmark.run_benchmark`)."""
    check_run_options(registry, args)
    _cluster_options(args)
    with output_folder(args.out):
        return _run(registry, args)


def _announce(registry, args, compiled: list):
    """The run's ``on_plan``: prints the plan's estimate, notes and compile notice; the units it will
    compile go to ``compiled`` (a :class:`CompileProgress` appended there)."""
    def show(plan, specs) -> None:
        estimate = plan.settings.get("estimate", {}).get("announcement")
        if estimate:
            print(f"denoise-bench run: {estimate}", file=sys.stderr)
        for note in plan.notes:
            print(f"denoise-bench run: {note}", file=sys.stderr)
        compiling = compile_notice(registry, plan)
        if compiling:
            print(f"denoise-bench run: {compiling}", file=sys.stderr)
            compiled.append(CompileProgress(registry, plan_units(registry, plan)))
        print(f"denoise-bench run: profile {args.profile}, {len(plan.jobs)} jobs on {len(specs)} scene(s), "
              f"{len(plan.skipped)} skipped; results in {args.out}", file=sys.stderr)

    return show


def _note(line: str) -> None:
    print(line, file=sys.stderr)


def _banner(executor) -> None:
    if hasattr(executor, "banner"):
        print(executor.banner(), file=sys.stderr)


def _renderer_settings(registry, args) -> dict:
    """``--renderer-option`` values per renderer, each checked against its factory's keyword arguments."""
    import inspect

    settings = _grouped(getattr(args, "renderer_option", []))
    for name, values in settings.items():
        factory = registry.get("renderer", name).factory
        try:
            inspect.signature(factory).bind(**values)
        except TypeError:
            accepted = [p for p in inspect.signature(factory).parameters if p not in ("self", "args", "kwargs")]
            raise ValueError(f"renderer {name!r} has no option(s) {sorted(set(values) - set(accepted))}; "
                             f"options: {accepted}") from None
    return settings


def _scene_roots(args) -> list:
    """The folders of scene folders of a run: ``--scene-root``, or for a run naming no scenes the default
    root (``$DENOISE_SCENES``, ``../shared/scenes``), where there is one (a line says so otherwise)."""
    if args.scene_root or args.scenes is not None or args.scene_dir:
        return list(args.scene_root)
    root = default_scene_root()
    if root is None:
        print(f"real tier skipped: no scene folders (set ${SCENES_ENV} or --scene-root to a folder of scene "
              "folders)", file=sys.stderr)
        return []
    return [root]


def _selection(registry, args, store, tasks, profile) -> list:
    notes: list = []
    specs = scene_selection(registry, store, args.scenes, args.scene_dir, tasks, scene_roots=_scene_roots(args),
                            real_resolution=profile.real_resolution, notes=notes)
    for line in notes:
        print(line, file=sys.stderr)
    return specs


def _compiled(progress: list):
    """The run's ``on_used``: one line as each announced unit finishes compiling (above the progress bar)."""
    def used(kind: str, name: str) -> None:
        line = progress[0](kind, name) if progress else None
        if line:
            from tqdm.auto import tqdm

            tqdm.write(f"denoise-bench run: {line}", file=sys.stderr)

    return used


def _run(registry, args) -> int:
    compiling: list = []
    outcome = run_benchmark(
        out=args.out, registry=registry, profile=args.profile, task=args.task, scenes=args.scenes,
        scene_dirs=args.scene_dir, filters=args.filters, metrics=args.metrics, renderer=args.renderer,
        backends=args.backend, spp=args.spp, seeds=args.seeds, frames=args.frames, resolution=args.resolution,
        reference_spp=args.reference_spp, reference_target=args.reference_target, repeats=args.repeats,
        timing_at=args.timing_at, timing_scene=args.timing_scene, emitters=args.emitters,
        params=_grouped(args.param), presets=dict(args.preset), grid=_grid(args.grid), nonfinite=args.nonfinite,
        executor=args.executor, executor_options=_cluster_options(args), timeout=args.timeout,
        disable=args.disable, cache_dir=args.cache_dir, use_cache=not args.no_cache, max_hours=args.max_hours,
        resume=args.resume,
        pictures=args.pictures, report_frames=args.report, save_outputs=args.save_outputs,
        progress=_progress(args), on_plan=_announce(registry, args, compiling), on_executor=_banner,
        on_used=_compiled(compiling),
        scene_roots=_scene_roots(args), renderer_settings=_renderer_settings(registry, args), on_note=_note,
    )
    df, store, plan = outcome.table, outcome.store, outcome.plan
    if args.csv:
        df.to_csv(args.out / "results.csv", index=False)
    hits, misses = sum(store.cache.hits.values()), sum(store.cache.misses.values())
    line = f"renders and references: {hits} reused from the cache, {misses} rendered"
    if args.resume:
        line += f"; {outcome.reused} stored jobs reused (--resume)"
        if outcome.removed:
            line += f", {outcome.removed} stored jobs of other settings removed"
    print(line)
    cost = measure_render_cost(store, plan, resolutions=[] if args.no_render_cost else None)
    write_render_cost(cost, args.out)
    if len(cost):
        print("renderer cost per frame: " + ", ".join(
                f"{r.renderer} {r.spp} spp {r.width}x{r.height} {r.render_ms:.3g} ms" for r in cost.itertuples()))
    _print_summary(df, registry, args.rank_by)
    _print_time_against_error(df, registry, args, read_render_cost(args.out))
    if args.report:
        index = write_report(args.out, registry, metrics=args.plot_metrics, budgets=args.budget or DEFAULT_BUDGETS,
                             rank_by=args.rank_by)
        print(f"\nreport written to {index}")
    errors = int(df[df.status == "error"].job_id.nunique())
    if errors:
        print(f"\n{errors} job(s) with errors; see 'message' in {args.out / 'results.parquet'}")
    return 1 if (args.strict and errors) else 0


def _print_time_against_error(df: pd.DataFrame, registry, args, render_cost) -> None:
    """The Pareto front and the best configuration within each budget, per task (where timed at 1280x720)."""
    ok = df[df.status == "ok"]
    if ok.empty:
        return
    board = leaderboard(df, registry.metrics, args.rank_by)
    metric = board.attrs.get("rank_by") if not board.empty else None
    if metric is None:
        return
    higher = bool(getattr(registry.metrics.get(metric), "higher_is_better", False))
    resolution = time_resolution(ok)
    for task in sorted(set(ok.task)):
        points = configuration_points(ok, metric, task, resolution=resolution, render_cost=render_cost)
        if points.time_ms.notna().sum() == 0:
            continue
        rendered = "filter + render" if points.render_ms.notna().any() else "filter only"
        shown = ["entry", "error", "time_ms", "filter_ms", "render_ms"]
        print(f"\nPareto front, task {task}: {metric} against ms per frame at {resolution_label(resolution)} "
              f"({rendered}):")
        print(format_table(pareto_front(points, "time_ms", "error", higher)[shown]))
        best = best_within(points, args.budget or DEFAULT_BUDGETS, "time_ms", "error", higher)
        print(f"Best within a frame budget, task {task}:")
        fits = best[best["entry"].notna()] if "entry" in best else best.iloc[:0]
        if not fits.empty:
            print(format_table(fits[["budget_ms", *[c for c in shown if c in fits]]]))
        fastest = points["time_ms"].min()
        for budget in best.loc[~best.index.isin(fits.index), "budget_ms"]:
            print(f"  {budget:g} ms: no entry fits (the fastest takes {fastest:.4g} ms)")


def cmd_report(registry, args) -> int:
    """Write the static HTML report of a stored run."""
    started = time.perf_counter()
    check_rank_by(read_results(args.dir), args.rank_by)
    index = write_report(args.dir, registry, out=args.out, metrics=args.plot_metrics,
                         budgets=args.budget or DEFAULT_BUDGETS, rank_by=args.rank_by)
    print(f"report written to {index} in {time.perf_counter() - started:.1f} s")
    return 0


def _print_summary(df: pd.DataFrame, registry, rank_by: str | None = None) -> None:
    ok = df[df.status == "ok"]
    if not ok.empty:
        print("\nSummary (mean over frames and seeds; ms_median = median per-frame filter time at the scene's "
              "resolution):")
        print(format_table(summary(ok)))
        boards = tier_boards(df, registry.metrics, rank_by)
        for task, tier, part in boards:
            print(f"\n{_board_title(task, part, df, tier if _several_tiers(boards) else None)}:")
            print(format_table(board_table(part, intervals="rank")))
        agreement = rank_agreement(boards)
        if len(agreement):
            print(f"\n{_AGREEMENT_TITLE}:")
            print(format_table(agreement))
        setups = timing_setups(df)
        if len(setups) > 1:
            print(f"\nNote: rows were timed on {len(setups)} machine setups ({'; '.join(setups)}); compare times "
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


_AGREEMENT_TITLE = ("Rank agreement between the tiers (Kendall's tau-b of the entries' scores on the two tiers' "
                    "leaderboards, per metric; 1 = same order, 0 = unrelated, -1 = reversed; filters = entries "
                    "scored on both)")


def _several_tiers(boards) -> bool:
    return len({tier for _, tier, _ in boards}) > 1


def _board_title(task: str, part: pd.DataFrame, df: pd.DataFrame, tier: str | None = None) -> str:
    rank_by = part.attrs.get("rank_by")
    direction = "higher" if part.attrs.get("higher_is_better") else "lower"
    timed = df[(df.task == task) & df[TIME_COLUMNS].notna().any(axis=1)]
    where = f"on {', '.join(sorted(set(timed.scene)))}" if len(timed) else "not measured in this run"
    scope = "" if tier is None else f", tier {tier or 'unrecorded'} ({', '.join(_tier_scenes(df, task, tier))})"
    return (f"Leaderboard, task {task}{scope}: ranked by {rank_by} ({direction} is better; mean over scenes of the "
            f"per-scene means, 95% bootstrap interval over seeds and frames; 'vs next' is a paired test against "
            f"the next entry; ms per frame at 1280x720 and 1920x1080 {where})")


def _tier_scenes(df: pd.DataFrame, task: str, tier: str) -> list[str]:
    ok = df[(df.status == "ok") & (df.task == task) & (df.tier == tier)]
    return sorted(set(ok.scene))


def cmd_show(registry, args) -> int:
    """Print the summary (or every row) and the leaderboard of a stored run."""
    if args.markdown is not None:
        markdown_file(args.markdown, args.dir)
    if (read_manifest(args.dir) or {}).get("kind") == "stress":
        return show_stress(args)
    df = read_results(args.dir)
    check_rank_by(df, args.rank_by)
    if args.all:
        print(format_table(df))
    else:
        _print_summary(df, registry, args.rank_by)
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
        boards = tier_boards(df, registry.metrics, args.rank_by)
        several = _several_tiers(boards)
        text = ["# Leaderboard", ""]
        if m and m.get("settings", {}).get("profile"):
            text += [_profile_line(m["settings"]["profile"]), ""]
        if m and m.get("command"):
            text += [f"Command: `{m['command']}`", ""]
        for task, tier, part in boards:
            heading = f"## Task {task}" + (f", tier {tier or 'unrecorded'}" if several else "")
            text += [heading, "", _board_title(task, part, df, tier if several else None) + ".", "",
                     to_markdown(board_table(part))]
        agreement = rank_agreement(boards)
        if len(agreement):
            text += ["## Rank agreement between the tiers", "", _AGREEMENT_TITLE + ".", "", to_markdown(agreement)]
        text += ["## Per scene", "", to_markdown(summary(df[df.status == "ok"])), provenance, ""]
        args.markdown.write_text("\n".join(text))
        print(f"markdown written to {args.markdown}")
    return 0


def _profile_line(profile: dict) -> str:
    """One sentence with a run's profile and the values it used."""
    res = profile.get("resolution") or "each scene's own"
    frames = profile.get("frames") or "all"
    target = profile.get("reference_target") or 0
    refs = (f"to a median relative standard error of {target:g}, at most {profile.get('reference_spp')} spp"
            if target else f"{profile.get('reference_spp') or 'the renderer default'} spp")
    timing = ", ".join(profile.get("timing") or []) or "none"
    return (f"Profile `{profile.get('name')}` with the values used: resolution {res}, frames per scene {frames}, "
            f"seeds {', '.join(map(str, profile.get('seeds', [])))}, references {refs}, "
            f"{profile.get('repeats')} timed calls per frame, timings at {timing} on `{profile.get('timing_scene')}`.")


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
    profile = get_profile(args.profile).with_overrides(resolution=args.resolution, frames=args.frames,
                                                       reference_spp=args.spp, reference_target=args.reference_target)
    store = RenderStore(registry, _cache(args), resolution=profile.resolution,
                        renderer_settings=_renderer_settings(registry, args))
    specs = _selection(registry, args, store, [args.task], profile)
    work = [_what_to_render(registry, spec, args, profile) for spec in specs]
    target = profile.reference_target
    estimate = check_work(reference_work(store, work, target or 0.0), store, args.max_hours)
    if estimate["announcement"]:
        print(f"denoise-bench render: {estimate['announcement']}", file=sys.stderr)
    if args.executor == "dask":
        return _render_on_cluster(registry, args, store, work, target)
    for spec, rname, spp, frames in work:
        with tqdm(total=frames * max(spp, 1), desc=f"{spec.name} ({rname}, {_reference_goal(spp, target)})",
                  unit="spp", disable=not sys.stderr.isatty()) as bar:
            records = [reference_record(store, spec.name, rname, t, spp=spp, target=target, chunk=args.chunk,
                                        progress=bar.update) for t in range(frames)]
        _print_references(store, spec, spp, target, records)
    return 0


def _reference_goal(spp: int, target: float) -> str:
    return f"{spp} spp" if not target else f"{target:g} median relative error, at most {spp} spp"


def _print_references(store, spec, spp: int, target: float, records) -> None:
    width, height = store.resolution_of(spec)
    done = ", ".join(f"{r.spp}/{r.error:.3g}" for r in records)
    print(f"{spec.name}: {len(records)} reference frame(s) at {_reference_goal(spp, target)}, {width}x{height}, in "
          f"the cache (samples per pixel / median relative standard error of each: {done})")


def cmd_profiles(registry, args) -> int:
    """List the run profiles: each one's settings (options of ``run`` override them)."""
    table = [p.as_dict() for p in PROFILES.values()]
    if args.format == "json":
        print(json.dumps(table, indent=2))
        return 0
    def cell(value) -> str:
        if value is None:
            return "-"
        if isinstance(value, list):
            return ",".join(map(str, value)) if value else "none"
        return str(value)

    rows = pd.DataFrame([{k: cell(v) for k, v in p.items() if k != "description"} for p in table])
    print(rows.to_string(index=False))
    print()
    for p in table:
        print(f"{p['name']}: {p['description']}")
    return 0


def cmd_export(registry, args) -> int:
    """Write every selected scene as a capture folder (multi-layer EXR frames, references, sidecar)."""
    from harness.export import export_scene

    store = RenderStore(registry, _cache(args), resolution=args.resolution,
                        renderer_settings=_renderer_settings(registry, args))
    specs = scene_selection(registry, store, args.scenes, args.scene_dir, [args.task], scene_roots=args.scene_root)
    for spec in specs:
        sidecar = export_scene(registry, store, spec, args.out / spec.name, task=args.task, renderer=args.renderer,
                               frames=args.frames, spp=args.spp, seed=args.seed, reference_spp=args.reference_spp,
                               half=args.half)
        print(f"{spec.name}: written to {sidecar.parent} (open it with --scene-dir {sidecar.parent})")
    return 0


def _what_to_render(registry, spec, args, profile) -> tuple:
    """(scene spec, renderer, reference spp, frames) of one scene of ``denoise-bench render``."""
    rname = args.renderer or choose_renderer(registry, spec, args.task)
    if rname is None:
        raise ValueError(f"no renderer serves task {args.task!r} for scene {spec.name!r} ({spec.kind})")
    rspec = registry.get("renderer", rname)
    if not rspec.references:
        raise ValueError(f"renderer {rname!r} makes no references")
    spp = rspec.reference_spp  # analytic references stay analytic unless --spp says otherwise
    if args.spp is not None or (rspec.reference_spp and profile.reference_spp is not None):
        spp = profile.reference_spp
    frames = spec.frames if profile.frames is None else min(spec.frames, profile.frames)
    return spec, rname, spp, frames


def _render_on_cluster(registry, args, store, work, target: float) -> int:
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

        requests = [(spec, spp, [renders.reference_record(spec.name, rname, t, spp=spp, target=target,
                                                          progress=tick) for t in range(frames)])
                    for spec, rname, spp, frames in work]
        for spec, spp, futures in requests:
            _print_references(store, spec, spp, target, [future.result() for future in futures])
    return 0


def cmd_bench(registry, args) -> int:
    """Time filters per frame at each resolution and thread count, with peers and floors on the same frame."""
    from harness.bench_markdown import bench_markdown, environment_line

    if args.markdown is not None:
        markdown_file(args.markdown)
    peers = args.peers if args.peers is not None else [p for p in DEFAULT_PEERS if p in registry.filters]
    store = RenderStore(registry, _cache(args))

    def say(line: str) -> None:
        if not args.quiet:
            print(f"bench: {line}", file=sys.stderr, flush=True)

    rounds = args.rounds or (args.repeats if args.baseline is not None or args.balance else None)
    threads = args.threads or ([1, max_threads()] if args.balance else [None])
    settings = dict(peers=peers, scene=args.scene, renderer=args.renderer, task=args.task,
                    resolutions=args.resolution, threads=threads, backend=args.backend, steady=args.steady or 0,
                    params=_grouped(args.param), presets=dict(args.preset), error=args.error, progress=say)
    with _executor(registry, args) as executor:
        if rounds is None:
            result = bench_filters(registry, store, executor, args.filters, repeats=args.repeats, **settings)
        else:
            result = bench_rounds(registry, store, executor, args.filters, rounds=rounds, baseline=args.baseline,
                                  balance=args.balance, **settings)
    timed = (f"frame {args.steady} after {args.steady} untimed frame(s)" if args.steady else "one frame (two for "
             "temporal filters: the second is timed)")
    how = (f"{rounds} rounds, the filters in turn, one call each" if rounds is not None
           else f"{args.repeats} timed calls in a row")
    print(f"scene {args.scene}, backend {args.backend}, {args.executor} executor, {timed}, {how}; "
          "cpu_ms = process CPU time per call (all threads), x_vs_PEER = peer ms / filter ms, "
          "x_of_floor = ms / floor ms, x_of_WxH = ms / ms at WxH, "
          "speedup_vs_Nt = ms at N threads / ms, peak_frames = peak / one float32 RGB frame")
    print(environment_line(result.environment))
    print(format_table(result.table))
    if not result.ratios.empty:
        print("\nRatios round by round: x = filter ms / other ms in the same round (median, min, max; x_cpu: "
              "process CPU time); against a floor x is x_of_floor, against the filter at 1 thread the inverse "
              "speed-up, against NAME@REV now / then")
        print(format_table(result.ratios))
    for resolution, order in result.order.items():
        shown = "; ".join(", ".join(labels) for labels in order[:2])
        print(f"call order at {resolution}, rounds 1-{min(2, len(order))} of {len(order)}: {shown}")
    if not result.stages.empty:
        print("\nPer-stage milliseconds (last timed call):")
        print(format_table(result.stages))
    if args.markdown is not None:
        args.markdown.write_text(bench_markdown(result, bench_command(args, peers)))
        print(f"markdown written to {args.markdown}")
    table = result.table
    return 0 if not table.empty and table["status"].eq("ok").any() else 1


def bench_command(args, peers) -> str:
    """The ``denoise-bench bench`` command line that repeats this bench (every setting spelled out)."""
    import shlex

    parts = ["denoise-bench", "bench", ",".join(args.filters), "--peers", ",".join(peers) or "''",
             "--scene", args.scene, "--task", args.task,
             "--resolution", ",".join(f"{w}x{h}" for w, h in args.resolution)]
    if args.renderer:
        parts += ["--renderer", args.renderer]
    if args.threads:
        parts += ["--threads", ",".join(map(str, args.threads))]
    parts += ["--backend", args.backend, "--repeats", str(args.repeats)]
    for option in ("rounds", "steady", "baseline"):
        if getattr(args, option) is not None:
            parts += [f"--{option}", shlex.quote(str(getattr(args, option)))]
    if args.balance:
        parts.append("--balance")
    if not args.error:
        parts.append("--no-error")
    for name, key, value in args.param:
        parts += ["--param", shlex.quote(f"{name}.{key}={json.dumps(value)}")]
    for name, chosen in args.preset:
        parts += ["--preset", f"{name}={chosen}"]
    if args.executor != "local":
        parts += ["--executor", args.executor]
    return " ".join(parts)


def cmd_train(registry, args) -> int:
    """Train a learned filter through its spec's ``trainer``."""
    spec = registry.get("filter", args.filter)
    if spec.trainer is None:
        raise ValueError(f"filter {spec.name!r} is not trainable")
    options = dict(args.option)
    keywords = inspect.signature(spec.trainer).parameters.values()
    if options and not any(p.kind is p.VAR_KEYWORD for p in keywords):
        raise ValueError(f"filter {spec.name!r}: its trainer takes no options (got {sorted(options)})")
    path = spec.trainer(seed=args.seed, output=args.output, quick=args.quick, **options)
    print(f"{spec.name}: wrote {path}")
    return 0
