"""A stress run: every (filter, backend) through the battery, fuzzing and replays, stored like a run.

Each case is a :class:`harness.stress.units.StressUnit` handed to an executor, so with the
``local`` executor it runs in the worker process: a segfault, ``os._exit`` or a hang is one
``crash``/``timeout`` row and the run goes on. The output folder is locked for the run and holds

``results.parquet``     the table of :mod:`harness.stress.table` (rewritten after every case)
``manifest.json``       ``"kind": "stress"``, the settings, cases, verdict counts, provenance
``reproducers/``        ``<filter>-<backend>.npz`` of each fuzzing failure (replay with
                        ``denoise-bench stress --replay FILE``)
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from harness.backends import cuda_available, resolve_backend
from harness.cache import atomic_write_bytes, clean_temporaries
from harness.executors.base import Executor
from harness.lock import FolderLock, check_out_dir
from harness.machine import machine_info, machine_label
from harness.plan import BACKEND_CHOICES, filter_params
from harness.results import write_table
from harness.stress.cases import CASES, StressCase, exemption
from harness.stress.check import CaseResult
from harness.stress.fuzz import fuzz
from harness.stress.reproducer import load_reproducer, replay_command, save_reproducer
from harness.stress.table import StressRow, counts, make_table, verdict
from harness.stress.units import StressUnit, case_result

RESULTS = "results.parquet"
REPRODUCERS = "reproducers"


@dataclass
class Target:
    """One filter on one backend with its parameters, or why it cannot run (``skip``)."""

    spec: object
    backend: str
    params: dict
    skip: str = ""

    @property
    def name(self) -> str:
        return self.spec.name


def make_targets(registry, filters: Sequence[str] | None = None, backends: Sequence[str] = ("auto",),
                 params: dict | None = None, presets: dict | None = None) -> list[Target]:
    """Every (filter, backend) to stress, parameters checked before any work.

    Parameters
    ----------
    registry : harness.Registry
    filters : list of str, optional
        Filter names (default: every registered filter).
    backends : list of str
        ``cpu``, ``cuda``, ``auto`` (cuda where a GPU is present) or ``all``.
    params : dict, optional
        ``{filter: {name: value}}`` overrides.
    presets : dict, optional
        ``{filter: preset}``.

    Raises
    ------
    KeyError, ValueError
        An unknown filter, backend, preset or parameter (one line).
    """
    params, presets = dict(params or {}), dict(presets or {})
    names = list(filters) if filters else sorted(registry.filters)
    specs = [registry.get("filter", n) for n in names]
    for owner in sorted(set(params) | set(presets)):
        if owner not in names:
            raise ValueError(f"parameters or a preset for filter {owner!r}, which is not stressed ({names})")
    bad = [b for b in backends if b not in BACKEND_CHOICES]
    if bad:
        raise ValueError(f"backend must be one of {BACKEND_CHOICES}, got {bad}")
    targets = []
    for spec in specs:
        values, _ = filter_params(spec, presets.get(spec.name), params.get(spec.name, {}))
        chosen = []
        for b in backends:
            chosen += list(spec.backends) if b == "all" else [resolve_backend(b, spec.backends) or b]
        for backend in dict.fromkeys(chosen):
            skip = ""
            if backend not in spec.backends:
                skip = f"filter {spec.name!r} has no {backend!r} backend (has {list(spec.backends)})"
            elif backend == "cuda" and not cuda_available():
                skip = "cuda backend: no GPU on this machine (numba.cuda.is_available() is False)"
            targets.append(Target(spec, backend, values, skip))
    return targets


def rerun_command(target: Target, case: str, reproducer: str = "") -> str:
    """The ``denoise-bench stress`` command line that runs one row of a stress run again.

    A battery case names the filter, backend, case and every parameter that differs from the
    filter's defaults; a fuzzing failure is replayed from its reproducer file; a replay names the
    file and the filter it ran on.
    """
    if case == "fuzz":
        return replay_command(reproducer) if reproducer else ""
    parts = ["denoise-bench", "stress", "--filters", target.name, "--backend", target.backend]
    if case.startswith("replay:"):
        parts += ["--replay", reproducer]
    else:
        parts += ["--cases", case]
    for key, value in sorted(target.params.items()):
        if value != target.spec.params.get(key):
            parts += ["--param", f"{target.name}.{key}={json.dumps(value, default=str)}"]
    return shlex.join(parts)


@dataclass
class StressOutcome:
    """What a stress run stored: the table, the manifest and the reproducers written."""

    table: pd.DataFrame
    manifest: dict = field(default_factory=dict)
    reproducers: list = field(default_factory=list)


def run_stress(registry, executor: Executor, out_dir: str | Path, targets: list[Target], *,
               cases: Sequence[StressCase] = (), fuzz_examples: int = 0, seed: int = 0,
               replay: str | Path | None = None, settings: dict | None = None, progress: bool = False,
               on_status: Callable[[str], None] | None = None) -> StressOutcome:
    """Run the battery, fuzzing and/or a replay for every target; store the table in ``out_dir``.

    Parameters
    ----------
    registry : harness.Registry
    executor : harness.executors.Executor
        Where cases run (``local``: a worker process that isolates crashes and hangs).
    out_dir : path
    targets : list of Target
        From :func:`make_targets`.
    cases : sequence of StressCase
        Battery cases to run on every target.
    fuzz_examples : int
        Examples per target for fuzzing (0: no fuzzing).
    seed : int
        Seed of the fuzzing search.
    replay : path, optional
        A reproducer file to run on every target.
    settings : dict, optional
        What was asked for (stored in the manifest).
    progress : bool
        Show a progress bar on standard error.
    on_status : callable, optional
        Receives one-line status messages: what starts, and each finished case (``[k/n] label:
        status``; with ``progress``, only the cases that fail, the bar counts the rest).
    """
    frames_info = load_reproducer(replay) if replay is not None else None
    out = check_out_dir(out_dir)
    with FolderLock(out):
        clean_temporaries(out)
        run = _Stress(registry, executor, out, targets, list(cases), fuzz_examples, seed, replay, frames_info,
                      settings or {}, progress, on_status or (lambda text: None))
        return run.execute()


class _Stress:
    def __init__(self, registry, executor, out, targets, cases, fuzz_examples, seed, replay, frames_info, settings,
                 progress, status):
        self.registry, self.executor, self.out, self.targets = registry, executor, out, targets
        self.cases, self.fuzz_examples, self.seed = cases, fuzz_examples, seed
        self.replay, self.frames_info, self.settings = replay, frames_info, settings
        self.progress, self.status = progress, status
        self.rows: list[StressRow] = []
        self.reproducers: list[Path] = []

    def execute(self) -> StressOutcome:
        (self.out / RESULTS).unlink(missing_ok=True)
        try:
            self._battery()
            for target in self.targets:
                if self.fuzz_examples:
                    self._fuzz(target)
                if self.frames_info is not None:
                    self._replay(target)
        finally:
            table = make_table(self.rows)
            write_table(table, self.out / RESULTS)
            manifest = self._manifest(table)
            atomic_write_bytes(self.out / "manifest.json",
                               json.dumps(manifest, indent=2, sort_keys=True, default=str).encode())
        return StressOutcome(table, manifest, self.reproducers)

    # ------------------------------------------------------------------ the battery
    def _battery(self) -> None:
        from tqdm.auto import tqdm

        tasks, slots = [], []
        for target in self.targets:
            for case in self.cases:
                why = target.skip or case.skip_reason(target.spec)
                slot = len(self.rows)
                placeholder = why or "not run (the stress run ended before this case)"
                self._add(target, case.name, case.group, CaseResult(status="skipped", message=placeholder),
                          write=False)
                if not why:
                    tasks.append(StressUnit(target.name, target.backend, target.params, case.name))
                    slots.append((slot, target, case))
        if not tasks:
            return
        skipped = len(self.targets) * len(self.cases) - len(tasks)
        self.status(f"{len(tasks)} (filter, case) pairs to run; {skipped} do not apply")
        bar = tqdm(total=len(tasks), disable=not self.progress, unit="case", dynamic_ncols=True, leave=False)
        try:
            for done, (index, outcome) in enumerate(self.executor.run(tasks), 1):
                slot, target, case = slots[index]
                bar.set_description(tasks[index].label)
                row = self._add(target, case.name, case.group, case_result(outcome, tasks[index].label), slot=slot)
                bar.update(1)
                if row.verdict == "fail" or not self.progress:
                    self.status(_case_line(done, len(tasks), tasks[index].label, row))
        finally:
            bar.close()

    # ------------------------------------------------------------------ fuzzing and replays
    def _evaluate(self, target: Target, label: str, frames: list, resets=(), flags=None) -> CaseResult:
        task = StressUnit(target.name, target.backend, target.params, label, frames=frames, resets=tuple(resets),
                          flags=dict(flags or {}))
        (_, outcome), = list(self.executor.run([task]))
        return case_result(outcome, task.label)

    def _fuzz(self, target: Target) -> None:
        if target.skip:
            self._add(target, "fuzz", "fuzz", CaseResult(status="skipped", message=target.skip))
            return
        spec = target.spec
        self.status(f"fuzz {target.name}/{target.backend}: {self.fuzz_examples} examples")
        start = time.perf_counter()
        found = fuzz(spec.requires | spec.optional, spec.temporal,
                     lambda frames: self._evaluate(target, "fuzz", frames),
                     examples_count=self.fuzz_examples, seed=self.seed)
        seconds = time.perf_counter() - start
        if found.example is None:
            result = CaseResult(notes=f"{found.tried} examples (seed {self.seed}), no failure; {seconds:.1f} s")
            self._add(target, "fuzz", "fuzz", result)
            self.status(f"fuzz {target.name}/{target.backend}: {result.notes}")
            return
        result = found.result
        path = self.out / REPRODUCERS / f"{target.name}-{target.backend}.npz"
        save_reproducer(path, found.frames, {
            "filter": target.name, "backend": target.backend, "params": target.params, "resets": [], "flags": {},
            "case": "fuzz", "status": result.status, "message": result.message, "seed": self.seed,
            "example": repr(found.example),
        })
        self.reproducers.append(path)
        first = found.frames[0]
        result.notes = (f"{found.tried} examples (seed {self.seed}); shrunk to {len(found.frames)} frame(s) of "
                        f"{first.height}x{first.width} with {len(found.example.edits)} edit(s); {seconds:.1f} s")
        if result.status in ("pass", "rejected"):
            result.notes += "; the minimal example passes when run again (a flaky failure)"
        self._add(target, "fuzz", "fuzz", result, reproducer=str(path))
        self.status(f"fuzz {target.name}/{target.backend}: {result.status}: {result.message[:160]}; {result.notes}")

    def _replay(self, target: Target) -> None:
        frames, info = self.frames_info
        label = f"replay:{Path(self.replay).name}"
        if target.skip:
            self._add(target, label, "replay", CaseResult(status="skipped", message=target.skip))
            return
        missing = sorted(target.spec.requires - set().union(*(f.channels for f in frames)))
        if missing:
            self._add(target, label, "replay", CaseResult(status="skipped", message=f"the reproducer lacks "
                                                                                     f"channel(s) {missing}"))
            return
        result = self._evaluate(target, label, frames, info.get("resets", ()), info.get("flags", {}))
        self._add(target, label, "replay", result, reproducer=str(self.replay))

    # ------------------------------------------------------------------ rows and manifest
    def _add(self, target: Target, case: str, group: str, result: CaseResult, reproducer: str = "",
             slot: int | None = None, write: bool = True) -> StressRow:
        """Add (or, at ``slot``, replace) the row of a case; rewrite the stored table unless ``write`` is false."""
        import numba

        exempt = exemption(target.spec, case) or ""
        row = StressRow(
            filter=target.name, backend=target.backend, params=json.dumps(target.params, sort_keys=True, default=str),
            case=case, group=group, status=result.status, verdict=verdict(result.status, exempt),
            message=result.message, exempt=exempt, notes=result.notes, frame=result.frame, calls=result.calls,
            height=result.height, width=result.width, ms_median=result.ms_median, ms_max=result.ms_max,
            peak_mb=result.peak_mb, reproducer=reproducer, command=rerun_command(target, case, reproducer),
            machine=machine_label(), threads=numba.get_num_threads(),
        )
        if slot is None:
            self.rows.append(row)
        else:
            self.rows[slot] = row
        if write:
            write_table(make_table(self.rows), self.out / RESULTS)
        return row

    def _manifest(self, table: pd.DataFrame) -> dict:
        from harness import __version__
        from harness.manifest import package_versions, provenance

        source = provenance()
        unknown = {t.name: sorted(k for k in t.spec.stress_exempt if not _matches_any(k))
                   for t in self.targets if any(not _matches_any(k) for k in t.spec.stress_exempt)}
        return {
            "kind": "stress",
            "harness_version": __version__,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "",
            "settings": self.settings,
            "cases": [c.name for c in self.cases],
            "filters": sorted({t.name for t in self.targets}),
            "verdicts": counts(table) if len(table) else {},
            "reproducers": [str(p) for p in self.reproducers],
            "unknown_exemptions": unknown,
            "git_commit": source["git_commit"],
            "git_dirty": source["dirty"],
            "installed_version": source["version"],
            "machine": machine_info(),
            "executor": self.executor.describe(),
            "python": sys.version.split()[0],
            "packages": package_versions(),
            "plugins": [r.as_dict() for r in self.registry.records],
        }


def _case_line(done: int, total: int, label: str, row: StressRow) -> str:
    """``[k/n] filter/backend stress case: status``, with the verdict and message of a failure."""
    line = f"[{done}/{total}] {label}: {row.status}"
    if row.verdict in ("fail", "declared", "stale"):
        line += f" ({row.verdict})"
    if row.message and row.verdict != "pass":
        line += f": {row.message[:160]}"
    return line


def _matches_any(pattern: str) -> bool:
    import fnmatch

    return pattern in ("fuzz",) or any(fnmatch.fnmatchcase(name, pattern) for name in CASES)


def read_stress(out_dir: str | Path) -> pd.DataFrame:
    """The stored table of a stress run."""
    path = Path(out_dir) / RESULTS
    if not path.exists():
        raise FileNotFoundError(f"no stress results in {out_dir}: {RESULTS} is missing")
    return make_table(pd.read_parquet(path).to_dict("records"))
