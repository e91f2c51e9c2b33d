"""The ``denoise-bench`` argument parser: every option checked before any work.

A bad value is a one-line message (``denoise-bench run: error: ...``) and exit status 2.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from harness.cache import default_cache_dir
from harness.executors import DASK_MISSING, DEFAULT_TIMEOUT_S, EXECUTOR_NAMES, EXECUTORS
from harness.plan import BACKEND_CHOICES, EMITTER_CHOICES, MAX_SEED
from harness.profiles import DEFAULT_PROFILE, PROFILES
from harness.rows import REAL_RESOLUTIONS
from harness.specs import TASKS

DEFAULT_OUT = Path("out") / "latest"
MAX_SIDE = 32768


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (no usage block) and exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def names(value: str) -> list[str]:
    """A comma-separated list of names, at least one."""
    items = [v.strip() for v in value.split(",") if v.strip()]
    if not items:
        raise argparse.ArgumentTypeError(f"needs at least one name, got {value!r}")
    return items


def _bound(high: int | None) -> str:
    return "2**63 - 1" if high == MAX_SEED else str(high)


def integers(low: int, high: int | None = None):
    """A comma-separated list of integers >= ``low`` (and <= ``high``)."""

    def parse(value: str) -> list[int]:
        try:
            items = [int(v) for v in value.split(",") if v.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be integers separated by commas, got {value!r}") from None
        if not items or min(items) < low:
            raise argparse.ArgumentTypeError(f"must be integers >= {low}, got {value!r}")
        if high is not None and max(items) > high:
            raise argparse.ArgumentTypeError(f"must be integers in [{low}, {_bound(high)}], got {value!r}")
        return items

    return parse


def integer(low: int, high: int | None = None):
    """One integer >= ``low`` (and <= ``high``)."""

    def parse(value: str) -> int:
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {value!r}") from None
        if number < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {number}")
        if high is not None and number > high:
            raise argparse.ArgumentTypeError(f"must be in [{low}, {_bound(high)}], got {number}")
        return number

    return parse


def thread_counts(value: str) -> list[int]:
    """``N,M,...`` or ``all``: thread counts, each in [1, Numba's limit], in order, duplicates dropped."""
    from harness.threads import max_threads

    limit = max_threads()
    counts = []
    for item in (v.strip() for v in value.split(",")):
        if item.lower() == "all":
            counts.append(limit)
            continue
        try:
            counts.append(int(item))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be thread counts (integers >= 1) or 'all', separated by commas, got {value!r}") from None
    bad = [n for n in counts if not 1 <= n <= limit]
    if bad:
        raise argparse.ArgumentTypeError(f"must be in [1, {limit}] (Numba's limit here: NUMBA_NUM_THREADS or the "
                                         f"core count), got {value!r}")
    return list(dict.fromkeys(counts))


def positive_seconds(value: str) -> float:
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {value!r}") from None
    if not number > 0 or number == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0, got {value!r}")
    return number


def resolution(value: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT``, each side in [1, 32768]."""
    try:
        w, h = value.lower().split("x")
        res = (int(w), int(h))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 1280x720, got {value!r}") from None
    if not (1 <= res[0] <= MAX_SIDE and 1 <= res[1] <= MAX_SIDE):
        raise argparse.ArgumentTypeError(f"resolution sides must be in [1, {MAX_SIDE}], got {value!r}")
    return res


def resolutions(value: str) -> list[tuple[int, int]]:
    """A comma-separated list of resolutions."""
    return [resolution(v) for v in names(value)]


def param(value: str) -> tuple[str, str, object]:
    """``FILTER.NAME=VALUE`` with a JSON value (a bare word is a string)."""
    try:
        key, raw = value.split("=", 1)
        name, field = key.split(".", 1)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must look like FILTER.NAME=VALUE, got {value!r}") from None
    if not name or not field:
        raise argparse.ArgumentTypeError(f"must look like FILTER.NAME=VALUE, got {value!r}")
    try:
        parsed = json.loads(raw)
    except json.JSONDecodeError:
        parsed = raw
    return name, field, parsed


def option(value: str) -> tuple[str, object]:
    """``KEY=VALUE`` with a JSON value (a bare word is a string)."""
    key, sep, raw = value.partition("=")
    if not key or not sep:
        raise argparse.ArgumentTypeError(f"must look like KEY=VALUE, got {value!r}")
    try:
        return key, json.loads(raw)
    except json.JSONDecodeError:
        return key, raw


def grid(value: str) -> tuple[str, str, list]:
    """``FILTER.NAME=V1,V2,...``: a swept parameter, each value JSON (a bare word is a string)."""
    name, field, _ = param(value)
    raw = value.split("=", 1)[1]
    items = [v.strip() for v in raw.split(",")]
    if not all(items):
        raise argparse.ArgumentTypeError(f"must look like FILTER.NAME=V1,V2,... with no empty value, got {value!r}")
    values = []
    for item in items:
        try:
            values.append(json.loads(item))
        except json.JSONDecodeError:
            values.append(item)
    return name, field, values


def budgets(value: str) -> list[float]:
    """Frame budgets in milliseconds, comma-separated, each finite and > 0."""
    try:
        items = [float(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be milliseconds separated by commas, got {value!r}") from None
    if not items or not all(0 < v < float("inf") for v in items):
        raise argparse.ArgumentTypeError(f"must be finite numbers of milliseconds > 0, got {value!r}")
    return sorted(set(items))


def preset(value: str) -> tuple[str, str]:
    """``FILTER=PRESET``."""
    name, _, chosen = value.partition("=")
    if not name or not chosen:
        raise argparse.ArgumentTypeError(f"must look like FILTER=PRESET, got {value!r}")
    return name, chosen


def backends(value: str) -> list[str]:
    items = names(value)
    bad = [b for b in items if b not in BACKEND_CHOICES]
    if bad:
        raise argparse.ArgumentTypeError(f"must be among {', '.join(BACKEND_CHOICES)}, got {', '.join(bad)}")
    return items


def fraction(value: str) -> float:
    """A number in [0, 1)."""
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {value!r}") from None
    if not 0 <= number < 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {value!r}")
    return number


def timing_resolutions(value: str) -> tuple:
    """``none`` or real resolutions among :data:`harness.rows.REAL_RESOLUTIONS`, comma-separated."""
    if value.strip().lower() == "none":
        return ()
    chosen = resolutions(value)
    allowed = [f"{w}x{h}" for w, h in REAL_RESOLUTIONS]
    bad = [f"{w}x{h}" for w, h in chosen if (w, h) not in REAL_RESOLUTIONS]
    if bad:
        raise argparse.ArgumentTypeError(f"filters are timed at {', '.join(allowed)} (or none), not {', '.join(bad)}")
    return tuple(dict.fromkeys(chosen))


def executor_name(allowed=EXECUTOR_NAMES):
    """An executor name among ``allowed``; ``dask`` where it is not installed says how to get it."""

    def parse(value: str) -> str:
        if value not in allowed:
            raise argparse.ArgumentTypeError(f"must be one of {', '.join(allowed)}, got {value!r}")
        if value == "dask" and value not in EXECUTORS:
            raise argparse.ArgumentTypeError(DASK_MISSING)
        return value

    return parse


def folder(value: str) -> Path:
    """A folder name (an empty one would be the current directory)."""
    if not value.strip():
        raise argparse.ArgumentTypeError("must name a folder, got ''")
    return Path(value)


def hours(value: str) -> float:
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of hours, got {value!r}") from None
    if not 0 < number < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number of hours > 0, got {value!r}")
    return number


def out_dir(value: str) -> Path:
    path = folder(value)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{value} is a file, not a folder")
    return path


def _add_profile(p: argparse.ArgumentParser) -> None:
    p.add_argument("--profile", choices=sorted(PROFILES), default=DEFAULT_PROFILE,
                   help=f"defaults of the run (default {DEFAULT_PROFILE}; 'denoise-bench profiles' lists them); "
                        "options given here override them")


def _add_rank_by(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rank-by", default=None, metavar="METRIC",
                   help="the metric the leaderboard ranks by (default: display_rmse where scored)")


def _add_report_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--budget", type=budgets, default=None, metavar="MS,...",
                   help="frame budgets in ms at 1280x720 for 'best within budget' (default 16,33)")
    p.add_argument("--plot-metrics", type=names, default=None, metavar="NAMES",
                   help="error metrics of the time-against-error plots (default: the ranking metric)")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--disable", type=names, default=[], metavar="NAMES",
                   help="plugins to disable, comma-separated (also $DENOISE_HARNESS_DISABLE)")


def _add_executor(p: argparse.ArgumentParser, timeout: float = DEFAULT_TIMEOUT_S) -> None:
    p.add_argument("--executor", type=executor_name(), default="local", metavar="{" + ",".join(EXECUTOR_NAMES) + "}",
                   help="where jobs run: local (a worker process that isolates crashes and hangs; default), "
                        "inline (this process, for debugging) or dask (a dask.distributed cluster; "
                        "extra [dask])")
    p.add_argument("--timeout", type=positive_seconds, default=timeout, metavar="SECONDS",
                   help=f"a job with no progress for this long is stopped (default {timeout:g}; "
                        "not enforced by the dask executor)")
    _add_cluster(p)


def _add_cluster(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="with --executor dask: the scheduler to use (default $DASK_SCHEDULER_ADDRESS; "
                        "none: a local cluster of worker processes)")
    p.add_argument("--workers", type=integer(1), default=None, metavar="N",
                   help="with --executor dask and no scheduler: worker processes of the local cluster "
                        "(default: one per core)")


def _add_selection(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenes", type=names, default=None, metavar="NAMES",
                   help="scenes to use, comma-separated (default: the built-in suite)")
    p.add_argument("--scene-dir", action="append", default=[], metavar="PATH",
                   help="also use the scene stored in this folder (e.g. a Mitsuba XML scene); repeatable")
    p.add_argument("--renderer", default=None, help="renderer for every scene (default: the preferred one per "
                                                    "scene kind and task)")
    p.add_argument("--resolution", type=resolution, default=None, metavar="WxH",
                   help="override every scene's resolution")
    p.add_argument("--frames", type=integer(1), default=None, help="at most this many frames per scene")
    p.add_argument("--cache-dir", type=folder, default=None,
                   help=f"render cache (default: $DENOISE_HARNESS_CACHE or {default_cache_dir()})")
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the render cache")


def build_parser() -> Parser:
    parser = Parser(prog="denoise-bench", description="Benchmark real-time Monte Carlo denoising and anti-aliasing "
                                                       "filters.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    run = sub.add_parser("run", help="render the scenes, run every filter, score and time them")
    _add_profile(run)
    _add_selection(run)
    run.add_argument("--task", choices=[*TASKS, "all"], default="all",
                     help="denoise, antialias or all (default: all; the leaderboard is per task)")
    run.add_argument("--filters", type=names, default=None, metavar="NAMES",
                     help="filters to run (default: every filter serving the task)")
    run.add_argument("--metrics", type=names, default=None, metavar="NAMES", help="metrics to score (default: all)")
    run.add_argument("--backend", type=backends, default=["auto"], metavar="B",
                     help="cpu, cuda, auto (cuda where a GPU is present) or all; comma-separated")
    run.add_argument("--spp", type=integers(1), default=[1], metavar="N",
                     help="samples per pixel of the noisy input (list)")
    run.add_argument("--seeds", type=integers(0, MAX_SEED), default=None, metavar="S",
                     help="seeds of the noisy input, each in [0, 2**63 - 1] (list; default: the profile's)")
    run.add_argument("--reference-spp", type=integer(1), default=None,
                     help="samples per pixel of references, the cap with a target (default: the profile's, else "
                          "the renderer's)")
    run.add_argument("--reference-target", type=fraction, default=None, metavar="E",
                     help="render references until their median relative standard error is E (0: exactly "
                          "--reference-spp; default: the profile's)")
    run.add_argument("--timing-at", type=timing_resolutions, default=None, metavar="WxH,...",
                     help="real resolutions every filter is also timed at: "
                          f"{','.join(f'{w}x{h}' for w, h in REAL_RESOLUTIONS)} or none (default: the profile's)")
    run.add_argument("--timing-scene", default=None, metavar="NAME",
                     help="the scene of those timings (default: the profile's, where selected)")
    run.add_argument("--emitters", choices=EMITTER_CHOICES, default="exclude",
                     help="pixels whose first hit is an emitter in the error metrics (default: exclude)")
    _add_rank_by(run)
    run.add_argument("--param", type=param, action="append", default=[], metavar="FILTER.NAME=VALUE",
                     help="set a filter parameter (JSON value); repeatable")
    run.add_argument("--preset", type=preset, action="append", default=[], metavar="FILTER=PRESET",
                     help="use a filter's named parameter preset; repeatable")
    run.add_argument("--grid", type=grid, action="append", default=[], metavar="FILTER.NAME=V1,V2,...",
                     help="sweep a filter parameter over values (JSON each); repeatable: every combination of a "
                          "filter's values is a configuration, each its own job")
    run.add_argument("--repeats", type=integer(1), default=None,
                     help="timed calls per frame (default: the profile's)")
    run.add_argument("--out", type=out_dir, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    run.add_argument("--csv", action="store_true", help="also write results.csv")
    run.add_argument("--pictures", action="store_true", help="write PNGs of every filter's first frame")
    run.add_argument("--save-outputs", action="store_true",
                     help="write every filter output as linear HDR OpenEXR under OUT/outputs/")
    run.add_argument("--resume", action="store_true",
                     help="keep stored jobs whose inputs are unchanged, run the rest")
    run.add_argument("--strict", action="store_true", help="exit 1 if any job errored")
    run.add_argument("--nonfinite", choices=["raise", "repair"], default="raise",
                     help="NaN/Inf in renderer output: fail the render (raise) or replace and count (repair)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--report", action="store_true",
                     help="keep the outputs of three frames per job (first seed) and write the HTML report to "
                          "OUT/report/ at the end (see 'denoise-bench report')")
    run.add_argument("--max-hours", type=hours, default=None, metavar="H",
                     help="refuse the run when its rendering is estimated to take longer than H hours (the estimate "
                          "is printed for runs over 10 minutes)")
    run.add_argument("--no-render-cost", action="store_true",
                     help="do not time the renderer per spp at the timing resolution (equal-time analysis)")
    _add_report_options(run)
    _add_executor(run)
    _add_common(run)

    plugins = sub.add_parser("plugins", help="list every plugin with its declarations and status")
    plugins.add_argument("--format", choices=["table", "json"], default="table")
    _add_common(plugins)

    show = sub.add_parser("show", help="summary table and leaderboard of a stored run")
    show.add_argument("dir", type=Path)
    _add_rank_by(show)
    show.add_argument("--all", action="store_true", help="print every row, not the summary")
    show.add_argument("--markdown", type=Path, default=None, metavar="FILE",
                      help="also write the summary and leaderboard as markdown to FILE")
    _add_common(show)

    report = sub.add_parser("report", help="write a static HTML report of a stored run (DIR/report/index.html)")
    report.add_argument("dir", type=Path)
    report.add_argument("--out", type=out_dir, default=None, help="report folder (default DIR/report; replaced)")
    _add_rank_by(report)
    _add_report_options(report)
    _add_common(report)

    profiles = sub.add_parser("profiles", help="list the run profiles (--profile) and their settings")
    profiles.add_argument("--format", choices=["table", "json"], default="table")
    _add_common(profiles)

    render = sub.add_parser("render", help="render references into the cache (chunked, resumable)")
    _add_profile(render)
    _add_selection(render)
    render.add_argument("--task", choices=list(TASKS), default="denoise",
                        help="whose references: denoise (default) or antialias")
    render.add_argument("--spp", type=integer(1), default=None,
                        help="reference samples per pixel, the cap with a target (default: the profile's, else the "
                             "renderer's)")
    render.add_argument("--reference-target", type=fraction, default=None, metavar="E",
                        help="stop at this median relative standard error (default: the profile's)")
    render.add_argument("--chunk", type=integer(1), default=64, help="samples per chunk between checkpoints")
    render.add_argument("--max-hours", type=hours, default=None, metavar="H",
                        help="refuse when the references are estimated to take longer than H hours")
    render.add_argument("--executor", type=executor_name(("inline", "dask")), default="inline",
                        metavar="{inline,dask}",
                        help="inline (this process; default) or dask (each chunk a task on a dask.distributed "
                             "cluster; extra [dask])")
    _add_cluster(render)
    _add_common(render)

    export = sub.add_parser("export", help="write scenes' frames, G-buffers and references as OpenEXR captures")
    _add_selection(export)
    export.add_argument("--out", type=out_dir, required=True, help="folder receiving one capture folder per scene")
    export.add_argument("--task", choices=list(TASKS), default="denoise", help="whose frames and references")
    export.add_argument("--spp", type=integer(1), default=1, help="samples per pixel of the frames (default 1)")
    export.add_argument("--seed", type=integer(0, MAX_SEED), default=0, help="seed of the frames (default 0)")
    export.add_argument("--reference-spp", type=integer(1), default=None,
                        help="samples per pixel of references (default: the renderer's)")
    export.add_argument("--half", action="store_true", help="store half floats (smaller; not bit-exact)")
    _add_common(export)

    bench = sub.add_parser("bench", help="time filters per frame against peers in the same process")
    bench.add_argument("filters", type=names, help="filter(s) to time, comma-separated")
    bench.add_argument("--peers", type=lambda v: [] if v.strip() == "" else names(v), default=None, metavar="NAMES",
                       help="peer filters timed on the same frame (default: opencv_jbf,oidn where registered)")
    bench.add_argument("--scene", default="synthetic-edges")
    bench.add_argument("--renderer", default=None)
    bench.add_argument("--task", choices=list(TASKS), default="denoise")
    bench.add_argument("--resolution", type=resolutions, default=[(1280, 720), (1920, 1080)], metavar="WxH,...")
    bench.add_argument("--threads", type=thread_counts, default=None, metavar="N,...|all",
                       help="time every filter and its floor at each of these thread counts (Numba, OpenCV, "
                            "PyTorch, OIDN), e.g. 1,2,all (default: the worker's own, all cores)")
    bench.add_argument("--backend", choices=["cpu", "cuda"], default="cpu")
    bench.add_argument("--repeats", type=integer(1), default=10,
                       help="timed calls of the timed frame, in a row, per filter (default 10)")
    bench.add_argument("--rounds", type=integer(1), default=None, metavar="N",
                       help="time every filter, peer, floor and baseline in one worker, in turn: N rounds of one "
                            "call each, in a new (seeded) order every round; ratios taken round by round")
    bench.add_argument("--baseline", default=None, metavar="REV",
                       help="also time each filter as it was at git revision REV (NAME@REV), in the same rounds")
    bench.add_argument("--steady", type=integer(1), default=None, metavar="N",
                       help="time frame N, after frames 0..N-1 (a temporal filter's steady state)")
    bench.add_argument("--balance", action="store_true",
                       help="thread balance: rounds at 1 and all threads (unless --threads), with each thread's "
                            "CPU time (busiest_share, thread_spread) and the per-round ratio to 1 thread")
    bench.add_argument("--no-error", dest="error", action="store_false",
                       help="time only: no reference and no rmse column (the raster renderer's 8x8 SSAA "
                            "reference needs about 6 GB at 1280x720, 13 GB at 1920x1080)")
    bench.add_argument("--param", type=param, action="append", default=[], metavar="FILTER.NAME=VALUE")
    bench.add_argument("--preset", type=preset, action="append", default=[], metavar="FILTER=PRESET")
    bench.add_argument("--cache-dir", type=folder, default=None)
    bench.add_argument("--markdown", type=Path, default=None, metavar="FILE",
                       help="also write the command, the machine and the tables as markdown to FILE")
    bench.add_argument("--quiet", action="store_true", help="no progress lines on standard error")
    _add_executor(bench)
    _add_common(bench)

    _add_stress(sub)

    train = sub.add_parser("train", help="train a learned filter and write its weights")
    train.add_argument("filter")
    train.add_argument("--seed", type=integer(0, MAX_SEED), default=0)
    train.add_argument("--output", type=Path, default=None,
                       help="weights file (default: the filter's shipped location)")
    train.add_argument("--quick", action="store_true", help="a short run (minutes) for smoke tests")
    train.add_argument("-o", "--option", type=option, action="append", default=[], metavar="KEY=VALUE",
                       help="an option of the filter's trainer (JSON value; repeatable), e.g. aa_rnn's "
                            "-o data=DIR -o sequences=1900 (see the filter's docs)")
    _add_common(train)
    return parser


DEFAULT_STRESS_OUT = Path("out") / "stress"
#: seconds a stress case may go without finishing a frame (4K frames included)
STRESS_TIMEOUT_S = 300.0


def reproducer_file(value: str) -> Path:
    """An existing file (a reproducer ``.npz`` written by ``--fuzz``)."""
    path = Path(value)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"no reproducer file {value!r}")
    return path


def _add_stress(sub) -> None:
    stress = sub.add_parser("stress", help="run filters through the numerical stress battery, fuzz them, or "
                                           "replay a reproducer")
    stress.add_argument("--filters", type=names, default=None, metavar="NAMES",
                        help="filters to stress, comma-separated (default: every registered filter)")
    stress.add_argument("--cases", type=names, default=None, metavar="NAMES",
                        help="cases, groups (colour, guide, shape, sequence, policy), fnmatch patterns, 'light' "
                             "or 'all', comma-separated (default: light, every case but the heavy 4K and 1,000-frame "
                             "ones; none with --fuzz or --replay)")
    stress.add_argument("--fuzz", type=integer(1), default=None, metavar="N",
                        help="generate N examples per filter with Hypothesis; shrink a failure to a reproducer")
    stress.add_argument("--seed", type=integer(0, MAX_SEED), default=0,
                        help="seed of the fuzzing search (default 0)")
    stress.add_argument("--replay", type=reproducer_file, default=None, metavar="FILE",
                        help="run a reproducer file again (on its filter, or on --filters)")
    stress.add_argument("--backend", type=backends, default=["auto"], metavar="B",
                        help="cpu, cuda, auto (cuda where a GPU is present) or all; comma-separated")
    stress.add_argument("--param", type=param, action="append", default=[], metavar="FILTER.NAME=VALUE",
                        help="set a filter parameter (JSON value); repeatable")
    stress.add_argument("--preset", type=preset, action="append", default=[], metavar="FILTER=PRESET",
                        help="use a filter's named parameter preset; repeatable")
    stress.add_argument("--out", type=out_dir, default=DEFAULT_STRESS_OUT,
                        help=f"output folder (default {DEFAULT_STRESS_OUT})")
    stress.add_argument("--markdown", type=Path, default=None, metavar="FILE",
                        help="also write the filter x case table as markdown to FILE")
    stress.add_argument("--quiet", action="store_true",
                        help="no progress (a bar on a terminal, else one line per case on standard error)")
    _add_executor(stress, timeout=STRESS_TIMEOUT_S)
    _add_common(stress)
