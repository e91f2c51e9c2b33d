"""``denoise-bench stress``: run the battery, fuzz, replay; print the filter x case table (and ``show`` it)."""

from __future__ import annotations

import sys
from collections.abc import Callable

import pandas as pd

from harness.cli.checks import markdown_file
from harness.executors.base import Executor
from harness.manifest import read_manifest
from harness.results import format_table, to_markdown


def run_stress_command(registry, args, make_executor: Callable[[], Executor]) -> int:
    """Run filters through the stress battery, fuzz them, or replay a reproducer; print the table.

    ``make_executor()`` builds the executor of ``--executor`` once every option is checked.
    """
    from harness.stress import load_reproducer, make_targets, run_stress, select_cases

    if args.markdown is not None:
        markdown_file(args.markdown, args.out)
    filters, backends, params = args.filters, args.backend, {}
    for name, key, value in args.param:
        params.setdefault(name, {})[key] = value
    if args.replay is not None:
        info = load_reproducer(args.replay)[1]
        if filters is None:  # the filter, backend and parameters it was found with; --param still overrides
            filters, backends = [info["filter"]], [info["backend"]]
            params[info["filter"]] = {**info.get("params", {}), **params.get(info["filter"], {})}
    battery = args.cases is not None or (args.fuzz is None and args.replay is None)
    cases = select_cases(args.cases or ["light"]) if battery else []
    if args.fuzz is not None:
        try:
            import hypothesis  # noqa: F401
        except ImportError:
            raise ValueError("--fuzz needs hypothesis (pip install 'denoise-harness[stress]')") from None
    targets = make_targets(registry, filters, backends, params, dict(args.preset))
    executor = make_executor()
    what = [f"{len(cases)} case(s)"] if battery else []
    what += [f"fuzzing {args.fuzz} examples (seed {args.seed})"] if args.fuzz else []
    what += [f"replay of {args.replay}"] if args.replay is not None else []
    print(f"denoise-bench stress: {len(targets)} filter/backend pair(s), {', '.join(what)}; results in {args.out}",
          file=sys.stderr)
    settings = {"filters": sorted({t.name for t in targets}), "backends": list(backends), "params": params,
                "presets": dict(args.preset), "cases": [c.name for c in cases], "fuzz": args.fuzz or 0,
                "seed": args.seed, "replay": str(args.replay) if args.replay else None, "timeout_s": args.timeout}
    bar = not args.quiet and sys.stderr.isatty()
    with executor:
        outcome = run_stress(registry, executor, args.out, targets, cases=cases, fuzz_examples=args.fuzz or 0,
                             seed=args.seed, replay=args.replay, settings=settings, progress=bar,
                             on_status=None if args.quiet else _status_printer(bar))
    _print_stress(outcome.table, args.markdown)
    for name, patterns in sorted(outcome.manifest.get("unknown_exemptions", {}).items()):
        print(f"denoise-bench stress: warning: filter {name!r} declares stress_exempt for {patterns}, which "
              f"match no case", file=sys.stderr)
    for path in outcome.reproducers:
        print(f"reproducer: {path}; replay with: denoise-bench stress --replay {path}")
    return 1 if (outcome.table.verdict == "fail").any() else 0


def _status_printer(bar: bool):
    """Status lines to standard error (above the progress bar when there is one)."""
    if bar:
        from tqdm.auto import tqdm

        return lambda text: tqdm.write(text, file=sys.stderr)
    return lambda text: print(text, file=sys.stderr, flush=True)


def failure_lines(df: pd.DataFrame) -> list[str]:
    """One line per failure, declared failure or stale declaration, each with the command that reruns it."""
    from harness.stress.table import failures

    lines = []
    for r in failures(df).itertuples():
        where = f" (frame {r.frame})" if r.frame >= 0 else ""
        line = f"{r.filter}/{r.backend} {r.case}: {r.verdict}, {r.status}{where}: {r.message}"
        if r.exempt:
            line += f" [declared: {r.exempt}]"
        lines.append(line)
        if r.command:
            lines.append(f"    rerun: {r.command}")
    return lines


def _print_stress(df: pd.DataFrame, markdown=None) -> None:
    from harness.stress.table import counts, matrix, per_filter

    print("Cells: the outcome and, where it passes, the median milliseconds per filter call.")
    print(format_table(matrix(df)))
    print()
    print(format_table(per_filter(df)))
    lines = failure_lines(df)
    if lines:
        print("\nFailures and declared exemptions:")
        print("\n".join("  " + line for line in lines))
    total = ", ".join(f"{n} {k}" for k, n in sorted(counts(df).items()))
    print("\n" + total)
    if markdown is not None:
        text = to_markdown(per_filter(df)) + "\n" + to_markdown(matrix(df))
        if lines:
            text += "\nFailures and declared exemptions:\n\n```\n" + "\n".join(lines) + "\n```\n"
        markdown.parent.mkdir(parents=True, exist_ok=True)
        markdown.write_text(text + f"\n{total}\n")
        print(f"markdown written to {markdown}")


def show_stress(args) -> int:
    """``denoise-bench show`` of a stress run's folder: the table, the failures, the provenance."""
    from harness.stress import read_stress

    df = read_stress(args.dir)
    if args.all:
        print(format_table(df))
    _print_stress(df, args.markdown)
    m = read_manifest(args.dir)
    commit = m.get("git_commit") or "unknown commit"
    if m.get("git_dirty"):
        commit += " (modified)"
    print(f"stress run: harness {m.get('harness_version')} at {commit}; {m['machine'].get('cpu')} "
          f"({m['machine'].get('numba_threads')} threads); created {m.get('created')}")
    return 0
