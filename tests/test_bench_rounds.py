"""``denoise-bench bench --rounds / --baseline / --steady / --balance`` and the timer's alternation.

No timing is asserted (timings are not tests): what is tested is who was called when, on
which frame and history, where a baseline came from, which rows and columns come out, and the
one-line errors.
"""

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness import FilterSpec, hookimpl, load_plugins
from harness.bench import bench_filters
from harness.bench_baseline import PROJECT_ROOT, plugin_path, resolve_revision
from harness.bench_rounds import RATIO_COLUMNS, bench_rounds
from harness.cache import Cache
from harness.executors import InlineExecutor
from harness.renders import RenderStore
from harness.threads import balance, max_threads
from harness.timer import alternate, round_order
from tests import bench_plugins
from tests.conftest import cli

#: (filter name, frame index, history indices) of every call of the logging filters
CALLS: list = []


class Logged:
    """Returns the colour; logs its name, the frame's index and the indices it has seen before."""

    name = "log_a"

    def __init__(self, backend="cpu"):
        self.seen = []

    def reset(self):
        self.seen = []

    def __call__(self, frame, sampler=None):
        CALLS.append((self.name, frame.meta.index, tuple(self.seen)))
        self.seen.append(frame.meta.index)
        return np.array(frame["color"], np.float32)


class LoggedB(Logged):
    name = "log_b"


class LoggedTemporal(Logged):
    name = "log_t"


class Plugin:
    @hookimpl
    def register_filters(self):
        return [FilterSpec(name="log_a", version="0", factory=Logged),
                FilterSpec(name="log_b", version="0", factory=LoggedB),
                FilterSpec(name="log_t", version="0", factory=LoggedTemporal, temporal=True)]


@pytest.fixture(scope="module")
def registry():
    return load_plugins(extra=[Plugin(), bench_plugins])


@pytest.fixture
def store(tmp_path):
    return lambda registry: RenderStore(registry, Cache(tmp_path / "cache"))


def run(registry, store, filters, **settings):
    CALLS.clear()
    settings = {"resolutions": [(32, 24)], "error": False, "rounds": 4, **settings}
    return bench_rounds(registry, store(registry), InlineExecutor(registry), filters, **settings)


def test_round_order_is_the_given_one_then_seeded_permutations():
    names = list("abcde")
    assert round_order(names, 0) == names
    orders = [round_order(names, r) for r in range(1, 6)]
    assert all(sorted(o) == names for o in orders) and len({tuple(o) for o in orders}) > 1
    assert orders == [round_order(names, r) for r in range(1, 6)]  # the same on every run
    for r in range(1, 40):  # never the given order again, never the previous round's
        assert round_order(names[:3], r) not in (names[:3], round_order(names[:3], r - 1))
    assert round_order([], 3) == [] and round_order(["a"], 3) == ["a"]
    assert round_order(["a", "b"], 1) == ["b", "a"] and round_order(["a", "b"], 2) == ["a", "b"]


def test_alternate_calls_in_the_recorded_order():
    log = []
    calls = {n: (lambda n=n: log.append(n)) for n in "xyz"}
    got = alternate(calls, 3)
    assert log[:3] == list("xyz")  # the warm-up calls
    assert log[3:] == [n for order in got.order for n in order]
    assert all(len(v) == 3 and min(v) >= 0 for v in got.ms.values()) and set(got.first_ms) == set("xyz")
    assert got.ratio("x", "y").shape == (3,)
    with pytest.raises(ValueError, match="rounds must be an integer >= 1"):
        alternate(calls, 0)


@pytest.mark.slow  # compiles the floor kernels (not cached on disk)
def test_rounds_alternate_call_by_call_in_the_recorded_order(registry, store):
    result = run(registry, store, ["log_a", "log_b"], peers=["passthrough"], rounds=5)
    order = result.order["32x24"]
    labels = ["log_a", "floor(log_a)", "log_b", "floor(log_b)", "passthrough", "floor(passthrough)"]
    assert len(order) == 5 and order[0] == labels and all(sorted(o) == sorted(labels) for o in order)
    logged = [n for n, _, _ in CALLS]
    # building: each filter's warm-up and one timed call; then the rounds; then one call for memory
    timed = logged[4:4 + 10]
    assert timed == [n for o in order for n in o if n in ("log_a", "log_b")]
    assert logged[14:] == ["log_a", "log_b"]
    table = result.table.set_index("filter")
    assert list(table.index) == ["log_a", "log_b", "passthrough"] and (table["status"] == "ok").all()
    assert (table["rounds"] == 5).all() and (table["ms_min"] <= table["ms_max"]).all()
    assert "x_vs_passthrough" in table
    ratios = result.ratios
    assert list(ratios.columns) == list(RATIO_COLUMNS) and (ratios["rounds"] == 5).all()
    pairs = set(zip(ratios["filter"], ratios["other"]))
    assert {("log_a", "passthrough"), ("log_b", "passthrough"), ("log_b", "log_a"),
            ("log_a", "floor(log_a)")} <= pairs
    assert (ratios["x_min"] <= ratios["x_median"]).all() and (ratios["x_median"] <= ratios["x_max"]).all()


def test_steady_times_frame_n_after_n_frames_of_history(registry, store):
    result = run(registry, store, ["log_t"], peers=[], rounds=3, steady=3, floors=False)
    assert (result.table["status"] == "ok").all()
    # frames 0-2 once each, then on frame 3 the warm-up, one call, the memory's run of frames 0-3 last
    assert [c[1] for c in CALLS[:3]] == [0, 1, 2] and [c[2] for c in CALLS[:3]] == [(), (0,), (0, 1)]
    assert CALLS[3:8] == [("log_t", 3, (0, 1, 2))] * 5  # the warm-up, the build's call, 3 rounds: same history
    assert [c[1] for c in CALLS[8:]] == [0, 1, 2, 3]


@pytest.mark.slow
def test_steady_in_a_row_times_frame_n_after_n_frames_of_history(registry, store):
    CALLS.clear()
    table = bench_filters(registry, store(registry), InlineExecutor(registry), ["log_t"], resolutions=[(32, 24)],
                          repeats=2, steady=3, error=False).table
    assert (table["status"] == "ok").all()
    assert [c for c in CALLS if c[1] == 3][:3] == [("log_t", 3, (0, 1, 2))] * 3  # warm-up + 2 timed calls


def test_steady_beyond_the_sequence_is_refused(registry, store):
    with pytest.raises(ValueError, match="scene 'synthetic-static' has 8 frame"):
        run(registry, store, ["log_t"], peers=[], scene="synthetic-static", steady=8)


def test_baseline_is_imported_from_the_revision_and_timed_beside_the_current_filter(registry, store):
    try:
        commit = resolve_revision("HEAD")
    except ValueError as exc:
        pytest.skip(f"not a git checkout: {exc}")
    _, folder = plugin_path(registry, "passthrough")
    result = run(registry, store, ["passthrough"], peers=[], baseline="HEAD", rounds=2, floors=False)
    table = result.table
    assert list(table["filter"]) == ["passthrough", "passthrough@HEAD"] and (table["status"] == "ok").all()
    assert ("passthrough", "passthrough@HEAD") in set(zip(result.ratios["filter"], result.ratios["other"]))
    module = sys.modules[f"_baseline_{commit[:12]}_passthrough"]
    where = Path(module.__file__)
    assert where.parent.name == Path(folder).name and where.parents[3].name.startswith("denoise-bench-baseline-")
    assert PROJECT_ROOT not in where.parents  # not the current plugin
    assert not where.parents[3].exists()  # the revision's folder is removed afterwards


def test_baseline_of_a_filter_outside_the_project_tree_is_refused(registry):
    with pytest.raises(ValueError, match="not a plugin package of this project"):
        plugin_path(registry, "alloc_frames")


def test_balance_columns_and_the_ratio_to_one_thread(registry, store):
    threads = list(dict.fromkeys([1, max_threads()]))
    result = run(registry, store, ["alloc_frames"], peers=[], threads=threads, balance=True, rounds=2, floors=False)
    table = result.table
    for column in ("busiest_share", "thread_spread"):
        assert table[column].dtype == np.float64
    assert list(table["threads"]) == threads
    shares = table["busiest_share"].dropna()
    assert ((shares > 0) & (shares <= 1)).all()
    if len(threads) > 1:
        row = result.ratios[(result.ratios["threads"] == threads[1]) & (result.ratios["other_threads"] == 1)]
        assert list(row["other"]) == ["alloc_frames"]
    assert balance({"1": 3.0, "2": 1.0}) == (0.75, 4 / 3)
    assert all(math.isnan(v) for v in balance({}))


@pytest.mark.slow  # compiles the floor kernels (not cached on disk)
def test_rounds_from_the_command_line(tmp_path):
    out = cli(["bench", "passthrough", "--peers", "", "--resolution", "32x24", "--rounds", "2", "--steady", "1",
               "--executor", "inline", "--no-error", "--quiet", "--cache-dir", tmp_path / "c",
               "--markdown", tmp_path / "b.md"])
    assert "Ratios round by round" in out.stdout and "call order at 32x24, rounds 1-2 of 2" in out.stdout
    markdown = (tmp_path / "b.md").read_text()
    assert "--rounds 2 --steady 1" in markdown and "#### Ratios round by round" in markdown


@pytest.mark.parametrize("args, message", [
    (["--baseline", "no-such-revision-here"], "--baseline no-such-revision-here: unknown git revision"),
    (["--rounds", "0"], "argument --rounds: must be >= 1"),
    (["--steady", "0"], "argument --steady: must be >= 1"),
    (["--rounds", "two"], "argument --rounds: must be an integer"),
])
def test_bad_options_are_one_line_and_exit_2(args, message, tmp_path):
    if args[0] == "--baseline":
        try:
            resolve_revision("HEAD")
        except ValueError as exc:
            pytest.skip(f"not a git checkout: {exc}")
    out = cli(["bench", "passthrough", "--peers", "", "--resolution", "32x24", "--executor", "inline",
               "--cache-dir", tmp_path / "c", *args], check=False)
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert out.returncode == 2 and len(lines) == 1 and message in lines[0], out.stderr


def test_revision_tree_is_removed_when_the_path_is_missing_there():
    from harness.bench_baseline import revision_tree

    try:
        resolve_revision("HEAD")
    except ValueError as exc:
        pytest.skip(f"not a git checkout: {exc}")
    with pytest.raises(ValueError, match="not found at that revision"):
        with revision_tree("HEAD", ["plugins/filters/no_such_plugin"]):
            pass
    left = subprocess.run(["git", "status", "--porcelain"], cwd=PROJECT_ROOT, capture_output=True, text=True)
    assert "no_such_plugin" not in left.stdout
