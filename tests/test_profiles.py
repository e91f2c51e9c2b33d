"""Run profiles (quick, paper): data, listing, overrides, the manifest, real-resolution timings in a run."""

import json

import numpy as np
import pandas as pd
import pytest

from harness import load_plugins
from harness.cache import Cache
from harness.plan import make_plan, timing_group, timing_groups
from harness.profiles import DEFAULT_PROFILE, PROFILES, get_profile
from harness.renders import RenderStore
from tests.test_run import bench
from tests.test_scene_animation import write_room


@pytest.fixture
def room(tmp_path):
    return write_room(tmp_path / "room")


def test_profiles_are_data_with_the_documented_values():
    assert DEFAULT_PROFILE == "quick" and set(PROFILES) == {"quick", "paper"}
    paper = get_profile("paper")
    assert paper.resolution == (1280, 720) and paper.frames is None and len(paper.seeds) >= 3
    assert 0 < paper.reference_target <= 0.01 and paper.reference_spp >= 4096
    quick = get_profile("quick")
    assert quick.resolution is None and quick.frames and len(quick.seeds) >= 2
    assert quick.timing == paper.timing == ((1280, 720), (1920, 1080))
    assert quick.with_overrides(frames=None, seeds=(4,)).seeds == (4,)
    assert quick.with_overrides(frames=None).frames == quick.frames
    with pytest.raises(KeyError, match="profiles: \\['paper', 'quick'\\]"):
        get_profile("slow")


def test_profiles_command_lists_them():
    out = bench(["profiles"])
    assert "quick" in out.stdout and "paper" in out.stdout and "1280x720" in out.stdout
    table = json.loads(bench(["profiles", "--format", "json"]).stdout)
    assert [p["name"] for p in table] == ["quick", "paper"]


def test_the_timing_group_is_the_profile_scene_or_the_first_one():
    reg = load_plugins()
    store = RenderStore(reg, Cache(enabled=False), resolution=(16, 12))
    scenes = [reg.scenes["synthetic-edges"], reg.scenes["synthetic-moving"]]
    plan = make_plan(reg, store, scenes, ["passthrough", "gaussian"], ["rmse"], spp=(2, 1), seeds=(3, 4),
                     timing_resolutions=((1280, 720),), timing_scene="synthetic-moving")
    group = timing_group(plan, "denoise", "synthetic-moving")
    assert (group.scene, group.spp, group.seed) == ("synthetic-moving", 1, 3)
    timed = [j for j in plan.jobs if j.timing]
    assert {j.filter for j in timed} == {"passthrough", "gaussian"} and all(j.timing == ((1280, 720),) for j in timed)
    # every configuration is timed at each spp of the run, on the first seed's groups
    assert all(j.scene == "synthetic-moving" and j.seed == 3 for j in timed)
    assert sorted((j.filter, j.spp) for j in timed) == [("gaussian", 1), ("gaussian", 2), ("passthrough", 1),
                                                         ("passthrough", 2)]
    assert [(g.spp, g.seed) for g in timing_groups(plan, "denoise", "synthetic-moving")] == [(1, 3), (2, 3)]
    other = make_plan(reg, store, scenes, ["passthrough"], ["rmse"], timing_resolutions=((1280, 720),),
                      timing_scene="atrium")
    assert [j.scene for j in other.jobs if j.timing] == ["synthetic-edges"]
    with pytest.raises(ValueError, match="filters are timed at"):
        make_plan(reg, store, scenes, ["passthrough"], ["rmse"], timing_resolutions=((640, 480),))


@pytest.mark.slow
def test_quick_run_has_seeds_intervals_and_real_resolution_times(tmp_path):
    out = bench(["run", "--scenes", "synthetic-moving,synthetic-edges", "--frames", "3", "--filters",
                 "passthrough,gaussian", "--quiet", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    profile = manifest["settings"]["profile"]
    assert profile["name"] == "quick" and profile["frames"] == 3 and profile["seeds"] == [0, 1, 2]
    assert manifest["seeds"] == [0, 1, 2]
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    timed = df[df.ms_1280x720.notna()]
    assert set(timed.scene) == {"synthetic-moving"} and set(timed.seed) == {0}
    assert set(timed["filter"]) == {"passthrough", "gaussian"} and (timed.ms_1920x1080 > 0).all()
    assert df.ms_1280x720.isna().sum() == len(df) - len(timed)
    assert "ranked by display_rmse" in out.stdout and "ms_1280x720" in out.stdout and "vs next" in out.stdout
    board = out.stdout.split("Leaderboard")[1]
    assert "[" in board  # intervals
    assert set(df.reference_spp) == {0} and (df.reference_noise == 0).all()  # analytic references


@pytest.mark.slow
def test_paper_profile_with_overrides_renders_references_to_a_target(tmp_path):
    bench(["run", "--profile", "paper", "--scenes", "synthetic-moving", "--filters", "passthrough", "--resolution",
           "24x16", "--frames", "2", "--seeds", "0,1", "--reference-spp", "64", "--timing-at", "none", "--quiet",
           "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    profile = manifest["settings"]["profile"]
    assert (profile["name"], profile["resolution"], profile["reference_target"]) == ("paper", "24x16", 0.01)
    quality = manifest["reference_quality"]
    assert len(quality) == 2 and all(q["spp"] == 64 and q["median_relative_error"] > 0.01 for q in quality.values())
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert (df.reference_spp == 64).all() and (df.reference_error > 0.01).all()
    assert np.isfinite(df.reference_noise).all() and (df.reference_noise > 0).all()
    assert df.ms_1280x720.isna().all()


def test_quick_sizes_the_real_tier_and_paper_renders_both_at_1280x720():
    assert get_profile("quick").real_resolution == (128, 72)
    paper = get_profile("paper")
    assert paper.resolution == (1280, 720) and paper.real_resolution is None  # one size for both tiers
    assert get_profile("quick").as_dict()["real_resolution"] == "128x72"


def test_scene_roots_join_the_real_tier_at_the_profile_size(room, tmp_path):
    from harness.renders import scene_selection

    root = tmp_path / "scenes"
    root.mkdir()
    room.rename(root / "room")
    (root / "notes").mkdir()  # no scene a plugin opens: named in one line, skipped
    reg = load_plugins()
    store = RenderStore(reg, Cache(enabled=False))
    notes = []
    specs = scene_selection(reg, store, ["synthetic-moving"], scene_roots=[root], real_resolution=(32, 18),
                            notes=notes)
    assert [(s.name, s.tier) for s in specs] == [("synthetic-moving", "procedural"), ("room", "real")]
    assert specs[1].resolution == (32, 18) and store.resolution(store.scene("room")) == (32, 18)
    assert specs[1].frames == 32 and len(notes) == 1 and "notes" in notes[0] and "\n" not in notes[0]
    # named no scenes: the root's folders join the suite (both tiers); a --scene-dir run is its folders alone
    both = scene_selection(reg, store, None, tasks=["denoise"], scene_roots=[root])
    suite = sorted(n for n, s in reg.scenes.items() if s.suite and "denoise" in s.tasks)
    assert [s.name for s in both] == [*suite, "room"] and {s.tier for s in both[:-1]} == {"procedural"}
    alone = scene_selection(reg, store, None, [root / "room"], tasks=["denoise"])
    assert [s.name for s in alone] == ["room"]


def test_the_default_root_is_denoise_scenes_else_the_shared_folder(monkeypatch, tmp_path, capsys):
    import argparse

    from harness.cli import commands
    from harness.renders import default_scene_root

    monkeypatch.setenv("DENOISE_SCENES", str(tmp_path))
    assert default_scene_root() == tmp_path
    monkeypatch.setenv("DENOISE_SCENES", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError, match="DENOISE_SCENES"):
        default_scene_root()
    args = argparse.Namespace(scene_root=[], scenes=None, scene_dir=[])
    monkeypatch.setattr(commands, "default_scene_root", lambda: None)
    assert commands._scene_roots(args) == []
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("real tier skipped")
    monkeypatch.setattr(commands, "default_scene_root", lambda: tmp_path)
    assert commands._scene_roots(args) == [tmp_path]
    # a run that names its scenes gets no default real tier
    assert commands._scene_roots(argparse.Namespace(scene_root=[], scenes=["cornell"], scene_dir=[])) == []


@pytest.mark.slow
def test_a_run_with_both_tiers_ranks_each_and_states_their_agreement(room, tmp_path):
    out = bench(["run", "--scenes", "synthetic-moving,synthetic-edges", "--scene-dir", room, "--frames", "2",
                 "--filters", "passthrough,gaussian,opencv_jbf", "--resolution", "24x16", "--seeds", "0,1",
                 "--reference-spp", "16", "--timing-at", "none", "--quiet", "--out", tmp_path / "o",
                 "--cache-dir", tmp_path / "c"])
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert dict(df.groupby("scene").tier.first()) == {"room": "real", "synthetic-edges": "procedural",
                                                      "synthetic-moving": "procedural"}
    text = out.stdout
    assert "tier procedural (synthetic-edges, synthetic-moving)" in text and "tier real (room)" in text
    assert "Rank agreement between the tiers" in text and "procedural vs real" in text
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["settings"]["tiers"]["room"] == "real"
    assert manifest["settings"]["renderer_settings"]["pathtracer"]["reference_pixel"] == "area"
    shown = bench(["show", tmp_path / "o", "--markdown", tmp_path / "board.md"]).stdout
    assert "tier real (room)" in shown and "procedural vs real" in shown
    markdown = (tmp_path / "board.md").read_text()
    assert "## Task denoise, tier real" in markdown and "## Rank agreement between the tiers" in markdown


def test_renderer_options_are_checked_against_the_factory():
    import argparse

    from harness.cli import commands

    reg = load_plugins()
    ok = argparse.Namespace(renderer_option=[("pathtracer", "jitter", True), ("pathtracer", "reference_pixel",
                                                                               "centre")])
    assert commands._renderer_settings(reg, ok) == {"pathtracer": {"jitter": True, "reference_pixel": "centre"}}
    with pytest.raises(ValueError, match=r"renderer 'pathtracer' has no option\(s\) \['speed'\]"):
        commands._renderer_settings(reg, argparse.Namespace(renderer_option=[("pathtracer", "speed", 2)]))
    with pytest.raises(KeyError):
        commands._renderer_settings(reg, argparse.Namespace(renderer_option=[("no-such-renderer", "x", 1)]))
