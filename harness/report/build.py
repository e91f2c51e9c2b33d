"""Assembling the report folder of a stored run: tables, plots, pictures, one ``index.html``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from harness.manifest import read_manifest
from harness.pareto import (
    DEFAULT_BUDGETS,
    best_within,
    configuration_points,
    pareto_front,
    resolution_label,
    time_resolution,
)
from harness.render_cost import read_render_cost
from harness.report import folder as report_folder
from harness.report import outputs as stored
from harness.report import pictures, plots
from harness.report.page import esc, figure, page, table
from harness.results import board_table, entry_labels, leaderboard, rank_agreement, read_results, tier_boards
from harness.rows import PER_FRAME_SUFFIX, metric_columns


def write_report(run_dir, registry, *, out: str | Path | None = None, metrics=None, budgets=DEFAULT_BUDGETS,
                 rank_by: str | None = None) -> Path:
    """Write the report of the run stored in ``run_dir``; returns the path of its ``index.html``.

    Parameters
    ----------
    run_dir : path
        A run's output folder (``results.parquet`` or ``jobs/``, ``manifest.json``, ``outputs/``).
    registry : harness.Registry
        For the metrics' directions.
    out : path, optional
        The report folder (default ``run_dir/report``): new, empty, or one an earlier report wrote,
        whose files are replaced (:mod:`harness.report.folder`; anything else is a ``ValueError``).
    metrics : list of str, optional
        Error metrics of the time-against-error plots (default: the leaderboard's ranking one).
    budgets : list of float
        Frame budgets in ms, drawn as vertical lines and answered ("best within B ms").
    rank_by : str, optional
        The leaderboard's ranking metric.
    """
    run_dir = Path(run_dir)
    out = report_folder.check_report_folder(out if out is not None else run_dir / "report", run_dir)
    foreign = report_folder.prepare(out)
    (out / "img").mkdir(exist_ok=True)
    df = read_results(run_dir)
    manifest = read_manifest(run_dir) or {}
    render_cost = read_render_cost(run_dir)
    board = leaderboard(df, registry.metrics, rank_by)
    rank_by = board.attrs.get("rank_by") if not board.empty else rank_by
    chosen = list(metrics or ([rank_by] if rank_by else []))
    higher = bool(getattr(registry.metrics.get(rank_by), "higher_is_better", False))
    sections = [_summary(manifest, df, render_cost)]
    sections += _leaderboards(df, registry, board, rank_by)
    ok = df[df.status == "ok"]
    ok = ok.assign(entry=entry_labels(ok)) if len(ok) else ok
    for task in sorted(set(ok.task)) if len(ok) else []:
        sections += _time_sections(ok, registry, task, chosen, budgets, out, render_cost)
        for scene in sorted(set(ok[ok.task == task].scene)):
            sections += _scene_section(run_dir, ok, task, scene, rank_by, higher, out)
    sections.append(_problems(df))
    (out / "index.html").write_text(page("denoise-bench report", sections))
    report_folder.finish(out, foreign)
    return out / "index.html"


def _summary(manifest: dict, df: pd.DataFrame, render_cost: pd.DataFrame) -> str:
    machine = manifest.get("machine", {})
    commit = manifest.get("git_commit") or "unknown"
    if manifest.get("git_dirty"):
        commit += " (modified)"
    profile = (manifest.get("settings") or {}).get("profile") or {}
    items = [
        ("command", manifest.get("command", "")),
        ("created", manifest.get("created", "")),
        ("harness", f"{manifest.get('harness_version', '')} at {commit}"),
        ("machine", f"{machine.get('cpu', '')}, {machine.get('cores', '')} cores, "
                    f"{machine.get('numba_threads', '')} Numba threads, GPU: {machine.get('gpu') or 'none'}"),
        ("python", manifest.get("python", "")),
        ("profile", ", ".join(f"{k}={v}" for k, v in profile.items() if k != "description")),
        ("seeds", ", ".join(map(str, manifest.get("seeds", [])))),
        ("jobs", f"{manifest.get('jobs', df.job_id.nunique())} ({manifest.get('skipped_jobs', 0)} skipped, "
                 f"{manifest.get('error_jobs', 0)} with errors)"),
    ]
    rows = "".join(f"<tr><th>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in items)
    html = f"<h2>Run</h2><table>{rows}</table>"
    if len(render_cost):
        shown = render_cost[["task", "scene", "renderer", "spp", "width", "height", "render_ms", "render_ms_min",
                             "render_ms_max", "repeats"]]
        html += ("<h3>Renderer cost per frame (added to filter times in the time-against-error plots)</h3>"
                 + table(shown, sortable=False))
    return html


def _leaderboards(df: pd.DataFrame, registry, board: pd.DataFrame, rank_by: str | None) -> list[str]:
    """One leaderboard per task and tier (scenes of both tiers: each ranked on its own, then their agreement)."""
    if board.empty:
        return ["<h2>Leaderboard</h2><p class='note'>no scored job</p>"]
    boards = tier_boards(df, registry.metrics, rank_by)
    several = len({tier for _, tier, _ in boards}) > 1
    out = []
    for task, tier, part in boards:
        direction = "higher" if part.attrs.get("higher_is_better") else "lower"
        scope = ""
        if several:
            scenes = sorted(set(df[(df.status == "ok") & (df.task == task) & (df.tier == tier)].scene))
            scope = f", tier {tier or 'unrecorded'} ({', '.join(scenes)})"
        out.append(f"<h2>Leaderboard, task {esc(task)}{esc(scope)}</h2><p class='note'>Ranked by "
                   f"{esc(part.attrs['rank_by'])} ({direction} is better): mean over scenes of per-scene means, 95% "
                   "bootstrap interval over seeds and frames; 'vs next' is a paired test against the next entry. "
                   "Click a column to sort.</p>" + table(board_table(part)))
    agreement = rank_agreement(boards)
    if len(agreement):
        out.append("<h2>Rank agreement between the tiers</h2><p class='note'>Kendall's tau-b of the entries' scores "
                   "on the two tiers' leaderboards, per metric: 1 = the same order, 0 = unrelated, -1 = reversed; "
                   "filters = entries scored on both. A ranking made on the procedural scenes alone transfers to "
                   "real content as far as tau says.</p>" + table(agreement, sortable=False))
    return out


def _time_sections(ok, registry, task, metrics, budgets, out, render_cost) -> list[str]:
    resolution = time_resolution(ok)
    at = resolution_label(resolution)
    rendered = len(render_cost) and (render_cost.task == task).any()
    what = ("filter time plus the renderer's cost at the configuration's spp" if rendered
            else "filter time only (the run measured no renderer cost)")
    sections = [f"<h2>Time against error, task {esc(task)}</h2><p class='note'>Each point is a configuration "
                f"(filter, parameters, backend, spp); time per frame at {at}: {what}. The line is the Pareto "
                "front (no other configuration is both faster and better); dashed lines are the frame budgets.</p>"]
    for metric in metrics:
        if metric not in ok:
            continue
        higher = getattr(registry.metrics.get(metric), "higher_is_better", False)
        overall = configuration_points(ok, metric, task, resolution=resolution, render_cost=render_cost)
        name = f"time-{stored.safe_name(task)}-{stored.safe_name(metric)}-overall.png"
        plots.time_against_error(overall, out / "img" / name, metric=metric, higher_is_better=higher, budgets=budgets,
                                 title=f"{task}, all scenes: {metric} against time", resolution=at)
        sections.append(figure(f"img/{name}", f"{metric}, all scenes", width=750))
        front = pareto_front(overall, "time_ms", "error", higher)
        best = best_within(overall, budgets, "time_ms", "error", higher)
        sections.append(f"<h3>Pareto front ({esc(metric)})</h3>" + table(_points_table(front), sortable=False))
        sections.append(f"<h3>Best within a frame budget ({esc(metric)})</h3>" + table(_points_table(best), False))
        per_scene = []
        for scene in sorted(set(ok[ok.task == task].scene)):
            points = configuration_points(ok, metric, task, scene, resolution=resolution, render_cost=render_cost)
            if points.time_ms.notna().sum() == 0:
                continue
            per_scene.append(best_within(points, budgets, "time_ms", "error", higher).assign(scene=scene))
            name = f"time-{stored.safe_name(task)}-{stored.safe_name(metric)}-{stored.safe_name(scene)}.png"
            plots.time_against_error(points, out / "img" / name, metric=metric, higher_is_better=higher,
                                     budgets=budgets, title=f"{task}, {scene}", resolution=at)
            sections.append(figure(f"img/{name}", f"{metric}, {scene}", width=560))
        if per_scene:
            best = pd.concat(per_scene, ignore_index=True)
            sections.append(f"<h3>Best within a frame budget per scene ({esc(metric)})</h3>"
                            + table(_points_table(best)))
    return sections


def _points_table(points: pd.DataFrame) -> pd.DataFrame:
    wanted = [c for c in ("scene", "budget_ms", "entry", "error", "time_ms", "filter_ms", "render_ms") if c in points]
    return points[wanted] if wanted else points


def _scene_section(run_dir, ok, task, scene, metric, higher, out) -> list[str]:
    rows = ok[(ok.task == task) & (ok.scene == scene)]
    sections = [f"<h2>{esc(scene)} ({esc(task)})</h2>"]
    names = {stored.output_name(r): r.entry for r in _best_per_filter(rows, metric, higher).itertuples()}
    folder = stored.folder(run_dir, task, scene)
    frames = sorted({int(p.stem.rpartition("-f")[2]) for p in folder.glob("reference-f*.npy")})
    if not frames:
        sections.append("<p class='note'>No stored outputs: run with <code>--report</code> to see the images.</p>")
    else:
        sections += _pictures(run_dir, task, scene, frames, names, int(rows.spp.min()), out)
    if metric and rows.frame.nunique() > 1:
        flicker = [c for c in metric_columns(rows)
                   if c.endswith(PER_FRAME_SUFFIX) and c != metric and rows[c].notna().any()]
        name = f"frames-{stored.safe_name(task)}-{stored.safe_name(scene)}.png"
        plots.over_frames(rows, out / "img" / name, metric=metric, flicker=flicker,
                          title=f"{scene}: {', '.join([metric, *flicker])} over the frames (mean over seeds)")
        what = " and ".join([metric, *flicker])
        sections.append(f"<h3>Over the frames</h3><p class='note'>{esc(what)} per frame, one line per "
                        "configuration; a per-frame flicker value at frame t compares the change from frame t-1 to "
                        "t with the reference's change.</p>" + figure(f"img/{name}", f"{what} per frame", width=750))
        for column in flicker:
            sequence = column[: -len(PER_FRAME_SUFFIX)]
            if sequence in rows and rows[sequence].notna().any():
                values = rows.groupby("entry")[sequence].mean().sort_values().reset_index()
                sections.append(f"<h3>Flicker ({esc(sequence)} over the sequence, mean over seeds)</h3>"
                                + table(values))
    return sections


def _best_per_filter(rows: pd.DataFrame, metric: str | None, higher: bool) -> pd.DataFrame:
    """One row per filter: its configuration with the best mean ``metric`` on these rows (the first without)."""
    entries = rows.drop_duplicates("entry")
    if not metric or metric not in rows or rows[metric].isna().all():
        return entries.drop_duplicates("filter")
    means = rows.groupby("entry")[metric].mean()
    entries = entries.assign(score=entries.entry.map(means))
    return entries.sort_values("score", ascending=not higher, na_position="last").drop_duplicates("filter")


def _pictures(run_dir, task, scene, frames, names, spp, out) -> list[str]:
    shown = frames[-1]  # the frame with the longest history
    ref = stored.load(run_dir, task, scene, "reference", shown)
    noisy = stored.load(run_dir, task, scene, f"input-spp{spp}", shown)
    results = {label: stored.load(run_dir, task, scene, name, shown) for name, label in sorted(names.items())}
    results = {k: v for k, v in results.items() if v is not None}
    windows = pictures.disagreement_crops(list(results.values()))
    base = f"{stored.safe_name(task)}-{stored.safe_name(scene)}"
    shape = next(i.shape for i in (ref, noisy, *results.values()) if i is not None)
    width = max(256, shape[1]) if shape[1] < 256 else None  # small scenes shown enlarged (pixelated)
    images = [("reference", ref), (f"noisy input, {spp} spp", noisy), *results.items()]
    html = [f"<h3>Frame {shown}: reference, input and every filter (crops where the filters disagree most)</h3>"]
    for k, (label, image) in enumerate(images):
        if image is None:
            continue
        name = f"{base}-{k}.png"
        pictures.write_display(out / "img" / name, pictures.outline(image, windows) if k == 0 else image)
        cells = [figure(f"img/{name}", label, width=width)]
        for c, window in enumerate(windows):
            crop_name = f"{base}-{k}-crop{c}.png"
            pictures.write_display(out / "img" / crop_name, pictures.crop(image, window))
            cells.append(figure(f"img/{crop_name}", f"crop {c + 1}"))
        html.append("<div>" + "".join(cells) + "</div>")
    if ref is not None and results:
        maps = {label: pictures.relmse_map(image, ref) for label, image in results.items()}
        vmax = max(float(np.percentile(m, 99)) for m in maps.values()) or 1.0
        plots.colour_bar(out / "img" / f"{base}-relmse-scale.png", vmax=vmax, label="relMSE (one scale for all)")
        html.append("<h3>Per-pixel error: FLIP error map (magma, 0 to 1) and relMSE</h3>"
                    + figure(f"img/{base}-relmse-scale.png", "relMSE colour bar"))
        for k, (label, image) in enumerate(results.items()):
            cells = []
            flip = pictures.flip_map(image, ref)
            if flip is not None:
                pictures.write_encoded(out / "img" / f"{base}-flip{k}.png", flip)
                cells.append(figure(f"img/{base}-flip{k}.png", f"{label}: FLIP", width=width))
            pictures.write_encoded(out / "img" / f"{base}-relmse{k}.png", plots.colour_map(maps[label], vmax))
            cells.append(figure(f"img/{base}-relmse{k}.png", f"{label}: relMSE", width=width))
            html.append("<div>" + "".join(cells) + "</div>")
    if len(frames) > 1:
        html.append(f"<h3>Frames {', '.join(map(str, frames))} side by side (the sequence at a glance)</h3>")
        for k, (name, label) in enumerate([("reference", "reference"), *sorted(names.items())]):
            strip = [stored.load(run_dir, task, scene, name, t) for t in frames]
            if any(s is None for s in strip):
                continue
            strip_name = f"{base}-strip{k}.png"
            pictures.write_display(out / "img" / strip_name, np.concatenate(strip, axis=1))
            html.append("<div>" + figure(f"img/{strip_name}", label) + "</div>")
    return html


def _problems(df: pd.DataFrame) -> str:
    bad = df[df.status != "ok"].drop_duplicates("job_id")
    if bad.empty:
        return "<h2>Skipped and errored jobs</h2><p class='note'>none</p>"
    shown = bad[["status", "task", "scene", "filter", "backend", "spp", "seed", "message"]].copy()
    shown["spp"] = shown.spp.map(lambda v: "" if v < 0 else v)
    shown["seed"] = shown.seed.map(lambda v: "" if v < 0 else v)
    return "<h2>Skipped and errored jobs</h2>" + table(shown.fillna(""))


__all__ = ["write_report"]
