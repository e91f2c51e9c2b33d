"""Executes a plan: renders (through the cache), the timing protocol, fault isolation, results.

Timing protocol (DESIGN.md): the first call of a filter on a new shape is its compile/warm-up
and is recorded as ``compile_ms``; then ``repeats`` calls are timed with
``time.perf_counter_ns`` and reported as median, min and max. CUDA work is synchronised before
the clock stops. Rendering, validation, I/O and metrics happen outside the timed region. A
temporal filter is deep-copied before each timed call so that every repeat starts from the same
history; the state after the last repeat carries on to the next frame. Jobs run one at a time
(timings need the machine to themselves).

Fault isolation: a filter that fails to build, raises, returns a wrong shape/dtype or non-finite
values gives an ``error`` row with a short message and the run goes on.
"""

from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from harness.buffers import ChannelError, Frame, apply_nonfinite_policy, check_filter_output
from harness.cache import Cache, array_hash, make_key
from harness.errors import short_error
from harness.results import combine, make_table, write_table

#: seed of every reference render: independent of the noisy frames' seeds
REFERENCE_SEED = 1_000_003


@dataclass
class RunOptions:
    """Knobs of a run.

    Attributes
    ----------
    repeats : int
        Timed calls per frame.
    nonfinite : {"raise", "repair"}
        Policy for NaN/Inf in renderer output.
    resume : bool
        Reuse stored job results in ``out_dir/jobs``.
    progress : bool
        Show a progress bar.
    pictures : bool
        Write PNG pictures of the first frame's outputs.
    """

    repeats: int = 3
    nonfinite: str = "raise"
    resume: bool = False
    progress: bool = True
    pictures: bool = False
    renderer_settings: dict = field(default_factory=dict)


class Runner:
    """Runs a :class:`harness.plan.Plan` and writes the results.

    Parameters
    ----------
    registry : harness.Registry
    plan : harness.plan.Plan
    cache : harness.cache.Cache
    out_dir : path
        Receives ``jobs/<job_id>.parquet`` as each job finishes and ``results.parquet``.
    options : RunOptions
    scenes : mapping name -> Scene, optional
        Scenes already built (e.g. opened from a folder); others come from their spec's factory.
    """

    def __init__(self, registry, plan, cache: Cache, out_dir, options: RunOptions | None = None, scenes=None):
        self.registry = registry
        self.plan = plan
        self.cache = cache
        self.out_dir = Path(out_dir)
        self.options = options or RunOptions()
        self._scenes = dict(scenes or {})
        self._renderers: dict = {}
        self.scene_hashes: dict[str, str] = {}
        self.reference_hashes: dict[str, str] = {}
        self.reused_jobs = 0
        self.metric_names = [m for m in self._all_metric_names()]

    # ------------------------------------------------------------------ plumbing
    def _all_metric_names(self) -> list[str]:
        names = []
        for g in self.plan.groups:
            for m in g.metrics.frame + g.metrics.sequence:
                if m.name not in names:
                    names.append(m.name)
            for m in g.metrics.skipped:
                if m not in names:
                    names.append(m)
        return names

    def scene(self, name: str):
        if name not in self._scenes:
            self._scenes[name] = self.registry.get("scene", name).factory()
        return self._scenes[name]

    def renderer(self, name: str):
        if name not in self._renderers:
            settings = self.options.renderer_settings.get(name, {})
            self._renderers[name] = self.registry.get("renderer", name).factory(**settings)
        return self._renderers[name]

    def _render_key(self, group, scene, frame_index, what, **extra) -> str:
        rspec = self.registry.renderers[group.renderer]
        renderer = self.renderer(group.renderer)
        return make_key(
            what=what,
            scene=scene.content_hash(),
            renderer=rspec.name,
            version=rspec.version,
            settings=renderer.settings(),
            frame=frame_index,
            resolution=self.resolution(scene),
            **extra,
        )

    def resolution(self, scene) -> tuple[int, int]:
        return tuple(self.plan.resolution or scene.resolution)

    def get_frame(self, group, scene, frame_index) -> Frame:
        """The noisy frame, from the cache or rendered (and stored)."""
        key = self._render_key(
            group, scene, frame_index, "frame", spp=group.spp, seed=group.seed, channels=sorted(group.channels)
        )
        stored = self.cache.load("frames", key)
        if stored is not None:
            return Frame.from_arrays(stored)
        renderer = self.renderer(group.renderer)
        frame = renderer.render(
            scene,
            frame_index,
            spp=group.spp,
            seed=group.seed,
            channels=group.channels,
            resolution=self.resolution(scene),
        )
        if not isinstance(frame, Frame):
            raise ChannelError(
                f"renderer {group.renderer!r}: render() returned {type(frame).__name__}, expected harness.Frame"
            )
        frame = Frame(frame.arrays(), frame.meta, owner=f"renderer {group.renderer!r}")
        self.cache.store("frames", key, frame.to_arrays())
        return frame

    def get_reference(self, group, scene, frame_index) -> np.ndarray:
        """The converged reference, from the cache or rendered (see :meth:`ensure_reference`)."""
        rspec = self.registry.renderers[group.renderer]
        spp = self.plan.reference_spp if self.plan.reference_spp is not None else rspec.reference_spp
        ref = self.ensure_reference(group.renderer, scene, frame_index, spp)
        self.reference_hashes[f"{scene.name}/{group.renderer}/{frame_index}"] = array_hash(ref)
        return ref

    def ensure_reference(
        self, renderer_name: str, scene, frame_index: int, spp: int, chunk: int = 64, bar=None
    ) -> np.ndarray:
        """Load or render the reference of ``frame_index`` at ``spp`` samples per pixel.

        Renderers with an ``accumulate`` method are run ``chunk`` samples at a time; the running
        sum is stored after every chunk, so an interrupted render resumes where it stopped. A
        renderer whose ``reference_spp`` is 0 has analytic references and is called once.
        """
        key = self.reference_key(renderer_name, scene, frame_index, spp)
        stored = self.cache.load("references", key)
        if stored is not None:
            if bar is not None:
                bar.update(max(spp, 1))
            return stored["reference"]
        renderer = self.renderer(renderer_name)
        resolution = self.resolution(scene)
        if not hasattr(renderer, "accumulate") or spp <= 0:
            ref = renderer.reference(scene, frame_index, spp=spp, seed=REFERENCE_SEED, resolution=resolution)
            ref = np.ascontiguousarray(ref, np.float32)
            if bar is not None:
                bar.update(max(spp, 1))
        else:
            partial = self.cache.load("partial", key)
            total = partial["sum"] if partial is not None else np.zeros((resolution[1], resolution[0], 3), np.float64)
            done = int(partial["done"]) if partial is not None else 0
            if bar is not None and done:
                bar.update(done)
            while done < spp:
                count = min(chunk, spp - done)
                total = total + renderer.accumulate(
                    scene, frame_index, first_sample=done, count=count, seed=REFERENCE_SEED, resolution=resolution
                )
                done += count
                if done < spp:
                    self.cache.store("partial", key, {"sum": total, "done": np.asarray(done)})
                if bar is not None:
                    bar.update(count)
            ref = (total / spp).astype(np.float32)
            self.cache.discard("partial", key)
        self.cache.store("references", key, {"reference": ref})
        return ref

    def reference_key(self, renderer_name: str, scene, frame_index: int, spp: int) -> str:
        """Cache key of a converged reference (shared by ``run`` and ``render``)."""
        rspec = self.registry.renderers[renderer_name]
        return make_key(
            what="reference",
            scene=scene.content_hash(),
            renderer=rspec.name,
            version=rspec.version,
            settings=self.renderer(renderer_name).settings(),
            frame=frame_index,
            spp=spp,
            seed=REFERENCE_SEED,
            resolution=self.resolution(scene),
        )

    # ------------------------------------------------------------------ running
    def run(self) -> pd.DataFrame:
        """Run every job; returns the results table (also written to ``out_dir``)."""
        jobs_dir = self.out_dir / "jobs"
        jobs_dir.mkdir(parents=True, exist_ok=True)
        tables = [make_table([self._skip_row(job, reason) for job, reason in self.plan.skipped], self.metric_names)]
        total = sum(len(g.jobs) * g.frames for g in self.plan.groups)
        bar = _progress(total, self.options.progress)
        try:
            for group in self.plan.groups:
                pending = []
                for job in group.jobs:
                    path = jobs_dir / f"{job.job_id}.parquet"
                    if self.options.resume and path.exists():
                        tables.append(pd.read_parquet(path))
                        self.reused_jobs += 1
                        bar.update(group.frames)
                    else:
                        pending.append(job)
                if not pending:
                    continue
                scene = None
                try:
                    scene = self.scene(group.scene)
                    self.scene_hashes[scene.name] = scene.content_hash()
                    bar.set_description(f"render {group.scene}")
                    frames, refs, repaired = self._inputs(group, scene)
                except Exception as exc:
                    msg = f"render failed: {short_error(exc)}"
                    for job in pending:
                        table = make_table([self._row(job, scene, -1, None, "error", msg)], self.metric_names)
                        write_table(table, jobs_dir / f"{job.job_id}.parquet")
                        tables.append(table)
                        bar.update(group.frames)
                    continue
                for job in pending:
                    bar.set_description(f"{job.filter}/{job.backend} on {job.scene}")
                    rows = self._run_job(job, group, scene, frames, refs, repaired, bar)
                    table = make_table(rows, self.metric_names)
                    write_table(table, jobs_dir / f"{job.job_id}.parquet")
                    tables.append(table)
                    write_table(combine(tables), self.out_dir / "results.parquet")
        finally:
            bar.close()
        df = combine(tables)
        write_table(df, self.out_dir / "results.parquet")
        return df

    def _inputs(self, group, scene):
        frames, refs, repaired = [], [], []
        rspec = self.registry.renderers[group.renderer]
        for t in range(group.frames):
            frame = self.get_frame(group, scene, t)
            frame, count = apply_nonfinite_policy(frame, self.options.nonfinite, owner=f"renderer {group.renderer!r}")
            frames.append(frame)
            repaired.append(count)
            refs.append(self.get_reference(group, scene, t) if rspec.references else None)
        return frames, refs, repaired

    def _run_job(self, job, group, scene, frames, refs, repaired, bar) -> list[dict]:
        spec = self.registry.filters[job.filter]
        rspec = self.registry.renderers[group.renderer]
        rows: list[dict] = []
        try:
            filt = spec.factory(backend=job.backend, **job.param_dict)
            filt.reset()
        except Exception as exc:
            bar.update(group.frames)
            return [self._row(job, scene, -1, frames[0], "error", f"filter could not be built: {short_error(exc)}")]
        visible = spec.requires | spec.optional
        outputs = []
        use_sampler = spec.adaptive and rspec.adaptive
        for t, frame in enumerate(frames):
            shown = frame.subset(visible & frame.channels)
            timing = {}
            try:
                filt, out, timing, samples = self._timed(filt, spec, job, group, scene, shown, t, use_sampler)
                check_filter_output(out, shown, owner=f"filter {job.filter!r}")
            except Exception as exc:
                rows.append(self._row(job, scene, t, frame, "error", short_error(exc), timing=timing))
                bar.update(group.frames - t)
                return rows
            notes = [f"{n} skipped: {r}" for n, r in group.metrics.skipped.items()]
            if repaired[t]:
                notes.append(f"{repaired[t]} non-finite input values repaired")
            scores = {}
            if refs[t] is not None:
                for m in group.metrics.frame:
                    try:
                        scores[m.name] = float(m.factory()(out, refs[t]))
                    except Exception as exc:
                        notes.append(f"{m.name} failed: {short_error(exc, 120)}")
            outputs.append(out)
            if self.options.pictures and t == 0:
                self._pictures(job, frame, out, refs[t])
            rows.append(
                self._row(
                    job,
                    scene,
                    t,
                    frame,
                    "ok",
                    "",
                    scores=scores,
                    timing=timing,
                    samples=samples,
                    notes="; ".join(notes),
                    repaired=repaired[t],
                )
            )
            bar.update(1)
        if group.metrics.sequence and rows:
            for m in group.metrics.sequence:
                try:
                    rows[-1][m.name] = float(m.factory()(outputs, refs))
                except Exception as exc:
                    rows[-1]["notes"] = "; ".join(
                        filter(None, [rows[-1]["notes"], f"{m.name} failed: {short_error(exc, 120)}"])
                    )
        return rows

    def _timed(self, filt, spec, job, group, scene, frame, t, use_sampler):
        """The timing protocol for one frame; returns (filter state, output, timing, samples)."""
        renderer = self.renderer(group.renderer) if use_sampler else None

        def new_sampler():
            if renderer is None:
                return None
            return renderer.sampler(
                scene, t, spp=group.spp, seed=group.seed, channels=group.channels, resolution=self.resolution(scene)
            )

        def call(instance, sampler):
            start = time.perf_counter_ns()
            out = instance(frame, sampler=sampler)
            if job.backend == "cuda":
                from numba import cuda

                cuda.synchronize()
            return out, (time.perf_counter_ns() - start) / 1e6

        stateful = spec.temporal
        timing = {"repeats": self.options.repeats}
        if t == 0:
            warm = copy.deepcopy(filt) if stateful else filt
            _, timing["compile_ms"] = call(warm, new_sampler())
        times = []
        state = filt
        out = sampler = None
        for _ in range(self.options.repeats):
            instance = copy.deepcopy(filt) if stateful else filt
            sampler = new_sampler()
            out, ms = call(instance, sampler)
            times.append(ms)
            state = instance
        timing.update(ms_median=float(np.median(times)), ms_min=float(min(times)), ms_max=float(max(times)))
        stage = getattr(state, "stage_ms", None)
        if stage:
            timing["stage_ms"] = json.dumps({k: round(float(v), 4) for k, v in stage.items()})
        if sampler is not None:
            samples = sampler.samples_used
        elif "spp" in frame:
            samples = int(frame["spp"].astype(np.int64).sum())
        else:
            samples = group.spp * frame.height * frame.width
        return state, out, timing, samples

    def _pictures(self, job, frame, out, ref) -> None:
        from harness.images import write_png

        folder = self.out_dir / "images" / job.scene
        write_png(folder / f"{job.filter}{'-' + job.preset if job.preset else ''}-{job.backend}-spp{job.spp}.png", out)
        write_png(folder / f"input-spp{job.spp}.png", frame["color"])
        if ref is not None:
            write_png(folder / "reference.png", ref)

    def _skip_row(self, job, reason) -> dict:
        return self._row(job, None, -1, None, "skipped", reason)

    def _row(
        self, job, scene, t, frame, status, message, *, scores=None, timing=None, samples=-1, notes="", repaired=0
    ):
        import numba

        h, w = (frame.height, frame.width) if frame is not None else (-1, -1)
        row = {
            "job_id": job.job_id,
            "scene": job.scene,
            "scene_hash": scene.content_hash() if scene is not None else "",
            "renderer": job.renderer,
            "filter": job.filter,
            "preset": job.preset,
            "params": job.params,
            "backend": job.backend,
            "spp": job.spp,
            "seed": job.seed,
            "frame": t,
            "width": w,
            "height": h,
            "status": status,
            "message": message,
            "notes": notes,
            "samples_used": samples,
            "threads": numba.get_num_threads(),
            "nonfinite_repaired": repaired,
        }
        row.update({m: math.nan for m in self.metric_names})
        row.update(scores or {})
        for k in ("compile_ms", "ms_median", "ms_min", "ms_max"):
            row[k] = (timing or {}).get(k, math.nan)
        row["repeats"] = (timing or {}).get("repeats", 0)
        row["stage_ms"] = (timing or {}).get("stage_ms", "")
        return row


def _progress(total: int, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, disable=not enabled, unit="frame", dynamic_ncols=True, leave=False)
