"""The plugin manager: entry points, duplicates, broken and disabled plugins, listing."""

import json
import subprocess
import sys

import pytest

from harness import PluginConflictError, load_plugins
from tests.conftest import bench_env

DUPLICATE = """
from harness import FilterSpec, hookimpl

class Same:
    def __init__(self, backend="cpu"): pass
    def reset(self): pass
    def __call__(self, frame, sampler=None): return frame["color"].copy()

@hookimpl
def register_filters():
    return [FilterSpec(name="gaussian", version="9", factory=Same)]
"""

HOOK_RAISES = """
from harness import hookimpl

@hookimpl
def register_filters():
    raise RuntimeError("cannot find my weights")
"""


def test_builtins_come_through_entry_points():
    reg = load_plugins()
    record = reg.record("filter", "passthrough")
    assert record.distribution == "denoise-harness"
    assert record.entry_point == "plugins.filters.passthrough"
    assert record.status == "ok" and len(record.source_hash) == 64
    assert {"synthetic"} <= set(reg.renderers) and {"rmse", "ssim", "flip", "temporal_error"} <= set(reg.metrics)


def test_duplicate_name_is_an_error_naming_both_distributions(fake_distribution):
    fake_distribution("evil-twin", {"twin": "twin_gaussian"}, {"twin_gaussian": DUPLICATE})
    with pytest.raises(PluginConflictError) as err:
        load_plugins()
    msg = str(err.value)
    assert "'gaussian'" in msg and "denoise-harness" in msg and "evil-twin" in msg


def test_disabling_resolves_a_duplicate(fake_distribution, monkeypatch):
    fake_distribution("evil-twin", {"twin": "twin_gaussian"}, {"twin_gaussian": DUPLICATE})
    reg = load_plugins(disable=["twin"])
    assert reg.filters["gaussian"].version == "1.0"
    monkeypatch.setenv("DENOISE_HARNESS_DISABLE", "twin, passthrough, rmse")
    reg = load_plugins()
    assert "passthrough" not in reg.filters and "rmse" not in reg.metrics and "psnr" in reg.metrics
    assert reg.record("module", "passthrough").status == "disabled"  # by entry-point name
    assert reg.record("metric", "rmse").status == "disabled"  # by plugin name
    with pytest.raises(KeyError, match="disabled"):
        reg.get("metric", "rmse")


def test_broken_plugins_are_listed_and_do_not_take_down_the_others(fake_distribution):
    fake_distribution(
        "broken-dist", {"missing": "no_such_module_here", "raiser": "hook_raises"}, {"hook_raises": HOOK_RAISES}
    )
    reg = load_plugins()
    broken = {r.name: r for r in reg.broken}
    assert "ModuleNotFoundError" in broken["missing"].error and broken["missing"].distribution == "broken-dist"
    assert "cannot find my weights" in broken["raiser"].error
    assert "passthrough" in reg.filters and "synthetic" in reg.renderers


@pytest.mark.slow
def test_plugins_command_lists_json_with_status(fake_distribution):
    path = fake_distribution("broken-dist", {"missing": "no_such_module_here"})
    out = subprocess.run(
        [sys.executable, "-m", "harness.cli", "plugins", "--format", "json"],
        capture_output=True,
        text=True,
        env=bench_env(path),
        check=True,
    )
    records = json.loads(out.stdout)
    by_name = {(r["kind"], r["name"]): r for r in records}
    assert by_name[("module", "missing")]["status"] == "broken"
    eaw_like = by_name[("filter", "gaussian")]
    assert eaw_like["declarations"]["params"] == {"sigma": 1.5} and eaw_like["distribution"] == "denoise-harness"
    table = subprocess.run(
        [sys.executable, "-m", "harness.cli", "plugins"],
        capture_output=True,
        text=True,
        env=bench_env(path),
        check=True,
    ).stdout
    assert "broken" in table and "median3" in table and "denoise-median-example" in table
