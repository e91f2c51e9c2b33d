"""What the scripts in ``benchmarks/`` share: the harness's clocks, its argument types, its baselines.

Per-frame filter timing is ``denoise-bench bench`` (``--rounds``, ``--baseline REV``,
``--steady N``, ``--balance``; docs/performance.md); the scripts here measure what it cannot
(renderers, the executors, internals of one plugin, quality studies) with the same
instruments:

- :func:`parser`: an ``argparse`` parser described by the script's docstring, with the
  harness's option types (:data:`resolution`, :data:`resolutions`, :data:`names`,
  :data:`integer`, :data:`integers`, :data:`thread_counts`: a bad value is a one-line error,
  exit status 2);
- :func:`alternate`, :func:`timed_call` (:mod:`harness.timer`): callables timed in turn, call by
  call, wall-clock and process CPU milliseconds; :func:`spread` and :func:`ratio_line` print
  them;
- :func:`baseline_package`: a package of this project as it was at a git revision, imported
  beside the current one (:mod:`harness.bench_baseline`);
- :func:`machine_line`: CPU, cores, load average, library versions (as ``bench`` prints them);
- :func:`using_threads` (:mod:`harness.threads`): every thread pool at one count.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as ``python benchmarks/NAME.py`` from anywhere
    sys.path.insert(0, str(ROOT))
os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from harness.bench_baseline import import_copy, module_name, resolve_revision, revision_tree  # noqa: E402
from harness.cli.parser import integer, integers, names, resolution, resolutions, thread_counts  # noqa: E402
from harness.threads import using_threads  # noqa: E402
from harness.timer import Alternation, alternate, timed_call  # noqa: E402

#: the third-party scenes, beside the project (absent: the scripts that need them skip them)
SHARED_SCENES = ROOT.parent / "shared" / "scenes"


def parser(doc: str, **kwargs) -> argparse.ArgumentParser:
    """A parser described by a script's docstring (first line; the rest as the epilog of ``--help``)."""
    head, _, rest = (doc or "").strip().partition("\n")
    return argparse.ArgumentParser(description=head, epilog=rest.strip() or None,
                                   formatter_class=argparse.RawDescriptionHelpFormatter, **kwargs)


def spread(values: Sequence[float], digits: int = 1) -> str:
    """``median [min-max]`` of ``values``."""
    v = np.asarray(values, np.float64)
    if not len(v):
        return "-"
    return f"{np.median(v):.{digits}f} [{v.min():.{digits}f}-{v.max():.{digits}f}]"


def ratio_line(result: Alternation, name: str, other: str, clock: str = "wall") -> str:
    """``NAME / OTHER (clock, per round): median M, range A-B``."""
    x = result.ratio(name, other, clock)
    return (f"{name} / {other} ({clock}, per round): median {np.nanmedian(x):.3f}, "
            f"range {np.nanmin(x):.3f}-{np.nanmax(x):.3f}")


def time_table(result: Alternation, width: int = 16, digits: int = 1) -> str:
    """One line per name: wall and CPU milliseconds, median [min-max] over the rounds."""
    width = max(width, *(len(n) for n in result.ms))
    lines = [f"{'':{width}s} {'wall ms median [min-max]':>28s} {'cpu ms median [min-max]':>28s}"]
    for name in result.ms:
        lines.append(f"{name:{width}s} {spread(result.ms[name], digits):>28s} "
                     f"{spread(result.cpu_ms[name], digits):>28s}")
    return "\n".join(lines)


@contextmanager
def baseline_package(rev: str, path: str) -> Iterator:
    """The package at ``path`` (relative to the project root) as it was at git revision ``rev``,
    imported under another name; its temporary folder is removed on exit."""
    with baseline_packages(rev, [path]) as (package,):
        yield package


@contextmanager
def baseline_packages(rev: str, paths: Sequence[str]) -> Iterator[list]:
    """:func:`baseline_package` for several packages of one revision (a list, in the order of ``paths``)."""
    commit = resolve_revision(rev)
    with revision_tree(commit, list(paths)) as tree:
        yield [import_copy(tree / path, module_name(commit, path.replace("/", "_"))) for path in paths]


def machine_line() -> str:
    """CPU, cores, Numba's thread limit, load average, date, Python and library versions."""
    from harness.bench import bench_environment
    from harness.bench_markdown import environment_line

    env = bench_environment()
    env["load_end"] = env["load_start"]
    return environment_line(env)


def run(main, argv=None) -> None:
    """Call ``main(argv)``; a user error (``ValueError``, a missing file) is one line and exit status 2."""
    try:
        code = main(argv)
    except (ValueError, FileNotFoundError) as exc:
        print(f"{Path(sys.argv[0]).name}: {exc}", file=sys.stderr)
        sys.exit(2)
    sys.exit(code or 0)


__all__ = ["ROOT", "SHARED_SCENES", "Alternation", "alternate", "baseline_package", "baseline_packages",
           "integer", "integers", "machine_line", "names", "parser", "ratio_line", "resolution", "resolutions",
           "run", "spread", "thread_counts", "time_table", "timed_call", "using_threads"]
