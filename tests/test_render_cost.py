"""The renderer's cost per frame at each spp: the timing protocol, the table, its file."""

import itertools

import pytest

from harness import load_plugins
from harness.cache import Cache
from harness.plan import make_plan
from harness.render_cost import FILE, measure_render_cost, read_render_cost, write_render_cost
from harness.renders import RenderStore


@pytest.fixture(scope="module")
def reg():
    return load_plugins(disable=[])


def test_one_untimed_call_then_repeats_timed_median_per_spp_and_resolution(reg, tmp_path):
    store = RenderStore(reg, Cache(tmp_path / "c"), resolution=(24, 16))
    scenes = [reg.scenes["synthetic-edges"], reg.scenes["synthetic-moving"]]
    plan = make_plan(reg, store, scenes, ["gaussian"], ["rmse"], spp=[1, 4], seeds=[0, 1], frames=1, repeats=3,
                     timing_resolutions=[(1280, 720)], timing_scene="synthetic-moving")
    durations, calls, now = itertools.count(1), itertools.count(), [0.0]

    def clock():  # the timed renders last 1, 2, 3, ... ms in turn
        if next(calls) % 2:
            now[0] += next(durations) / 1000.0
        return now[0]

    cost = measure_render_cost(store, plan, resolutions=[(32, 24), (16, 8)], clock=clock)
    assert list(zip(cost.spp, cost.width)) == [(1, 32), (1, 16), (4, 32), (4, 16)]
    assert set(cost.scene) == {"synthetic-moving"} and set(cost.seed) == {0} and set(cost.repeats) == {3}
    assert list(cost.render_ms) == pytest.approx([2.0, 5.0, 8.0, 11.0])  # medians of 1,2,3 / 4,5,6 / ...
    assert list(cost.render_ms_min) == pytest.approx([1.0, 4.0, 7.0, 10.0])
    write_render_cost(cost, tmp_path)
    assert read_render_cost(tmp_path).equals(cost)
    write_render_cost(cost.iloc[:0], tmp_path)  # nothing measured: no stale file
    assert not (tmp_path / FILE).exists() and read_render_cost(tmp_path).empty
    assert measure_render_cost(store, plan, resolutions=[]).empty
