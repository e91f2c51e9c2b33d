"""Every input of a job is in its identity; --resume reuses only unchanged jobs; the cache heals."""

import json
import os
import stat

import numpy as np
import pandas as pd
import pytest

from harness import load_plugins
from harness.cache import PROCESS_START, TEMP_GRACE_S, Cache, atomic_write_bytes, clean_temporaries
from harness.manifest import provenance
from harness.plan import make_plan
from harness.renders import RenderStore
from tests.test_run import bench

RUN = ["run", "--scenes", "synthetic-edges,synthetic-moving", "--filters", "passthrough,gaussian", "--quiet",
       "--repeats", "1", "--executor", "inline", "--seeds", "0", "--timing-at", "none", "--frames", "16"]


def _ids(**options):
    reg = load_plugins()
    store = RenderStore(reg, resolution=options.pop("resolution", (16, 12)))
    plan = make_plan(reg, store, [reg.scenes["synthetic-moving"]], ["gaussian"], options.pop("metrics", ["rmse"]),
                     **options)
    return {j.job_id for j in plan.jobs}


def test_the_job_id_changes_with_every_input_that_changes_rows():
    base = _ids()
    assert _ids() == base
    for changed in (dict(resolution=(32, 24)), dict(frames=2), dict(metrics=["rmse", "ssim"]), dict(repeats=5),
                    dict(reference_spp=8), dict(seeds=[1]), dict(spp=[2]), dict(params={"gaussian": {"sigma": 2.0}}),
                    dict(nonfinite="repair")):
        assert _ids(**dict(changed)) != base, changed


@pytest.mark.slow
def test_resume_never_mixes_settings(tmp_path):
    out, cache = tmp_path / "o", tmp_path / "c"
    bench([*RUN, "--resolution", "64x48", "--out", out, "--cache-dir", cache])
    resumed = bench([*RUN, "--resolution", "16x12", "--out", out, "--cache-dir", cache, "--resume"])
    assert "0 stored jobs reused (--resume), 4 stored jobs of other settings removed" in resumed.stdout
    df = pd.read_parquet(out / "results.parquet")
    assert set(zip(df.width, df.height)) == {(16, 12)}
    shown = bench(["show", out, "--all"])
    assert " 64 " not in shown.stdout  # show reads the job files: no stale job is left among them
    again = bench([*RUN, "--resolution", "16x12", "--out", out, "--cache-dir", cache, "--resume"])
    assert "4 stored jobs reused (--resume)" in again.stdout
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["scenes"]) == {"synthetic-edges", "synthetic-moving"} and manifest["reused_jobs"] == 4
    assert len(manifest["references"]) == 1 + 16  # every frame of the stored table


@pytest.mark.slow
def test_resume_after_a_partial_second_invocation_keeps_the_manifest_whole(tmp_path):
    out, cache = tmp_path / "o", tmp_path / "c"
    bench([*RUN, "--frames", "2", "--out", out, "--cache-dir", cache])
    bench([*RUN, "--frames", "2", "--out", out, "--cache-dir", cache, "--resume"])
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["scenes"]) == {"synthetic-edges", "synthetic-moving"}
    assert manifest["jobs"] == 4 and manifest["reused_jobs"] == 4


@pytest.mark.slow
def test_a_corrupted_cache_entry_is_rendered_again_with_a_warning(tmp_path):
    out, cache = tmp_path / "o", tmp_path / "c"
    first = bench([*RUN, "--frames", "1", "--out", out, "--cache-dir", cache])
    entries = sorted((cache / "frames").rglob("*.npz"))
    data = bytearray(entries[0].read_bytes())
    entries[0].write_bytes(bytes(data[: len(data) // 2]))  # truncated
    data = bytearray(entries[1].read_bytes())
    data[len(data) // 2] ^= 0xFF  # one flipped byte
    entries[1].write_bytes(bytes(data))
    second = bench([*RUN, "--frames", "1", "--out", tmp_path / "o2", "--cache-dir", cache])
    assert second.stderr.count("is unreadable") >= 1 and str(entries[0].name) in second.stderr
    assert "removed, rendering it again" in second.stderr
    a = pd.read_parquet(out / "results.parquet")
    b = pd.read_parquet(tmp_path / "o2" / "results.parquet")
    assert set(b.status) == {"ok"} and np.array_equal(a.rmse.to_numpy(), b.rmse.to_numpy())
    third = bench([*RUN, "--frames", "1", "--out", tmp_path / "o3", "--cache-dir", cache])
    assert "is unreadable" not in third.stderr and "0 rendered" in third.stdout, first.stdout


def test_result_files_are_readable_by_others(tmp_path):
    path = tmp_path / "f.bin"
    old = os.umask(0o022)
    try:
        atomic_write_bytes(path, b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_abandoned_temporary_files_are_cleaned(tmp_path):
    old = tmp_path / "frames" / "ab" / ".abcd.npz.x1y2.tmp"
    old.parent.mkdir(parents=True)
    old.write_bytes(b"half")
    abandoned = PROCESS_START - TEMP_GRACE_S - 3600  # an hour before this process could have written it
    os.utime(old, (abandoned, abandoned))
    fresh = tmp_path / "frames" / "ab" / ".efgh.npz.z9.tmp"
    fresh.write_bytes(b"being written")
    keep = tmp_path / "frames" / "ab" / "abcd.npz"
    keep.write_bytes(b"entry")
    assert clean_temporaries(tmp_path) == 1
    assert not old.exists() and fresh.exists() and keep.exists()


def test_provenance_comes_from_the_project_not_the_current_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    info = provenance()
    assert info["version"]
    if (pytest.importorskip("harness").__file__ or "").startswith(str(tmp_path)):
        pytest.skip("unexpected layout")
    manifest_run = bench([*RUN, "--frames", "1", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["git_commit"] == info["git_commit"] and "installed_version" in manifest, manifest_run.stdout
    if info["git_commit"]:
        assert len(info["git_commit"]) == 40 and isinstance(info["dirty"], bool)


def test_cache_load_survives_any_garbage(tmp_path):
    cache = Cache(tmp_path)
    cache.store("frames", "k" * 64, {"a": np.ones(3)})
    cache.path("frames", "k" * 64).write_bytes(b"not a zip at all")
    with pytest.warns(UserWarning, match="unreadable"):
        assert cache.load("frames", "k" * 64) is None
    assert not cache.path("frames", "k" * 64).exists()
