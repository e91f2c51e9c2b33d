"""``denoise-bench report``: a self-contained HTML folder built from a small real run, opened in a browser."""

import re
import shutil
import subprocess

import numpy as np
import pytest

from harness.report import pictures
from harness.report.outputs import kept_frames, safe_name
from harness.report.page import table
from tests.test_run import bench

RUN = ["run", "--scenes", "synthetic-moving,synthetic-edges", "--frames", "3", "--resolution", "48x32", "--seeds",
       "0", "--filters", "gaussian,eaw", "--grid", "eaw.iterations=1,3", "--spp", "1,2", "--repeats",
       "1", "--timing-at", "none", "--reference-spp", "16", "--executor", "inline", "--quiet"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A small real run made with ``--report`` (its report is in ``run_dir/report``)."""
    root = tmp_path_factory.mktemp("report")
    out = bench([*RUN, "--report", "--out", root / "o", "--cache-dir", root / "c"])
    assert "report written to" in out.stdout
    assert "Pareto front, task denoise" in out.stdout and "Best within a frame budget" in out.stdout
    return root / "o"


def referenced(index):
    html = index.read_text()
    return html, re.findall(r'(?:src|href)="([^"]+)"', html)


@pytest.mark.slow
def test_report_is_a_self_contained_folder_whose_images_all_exist(run_dir):
    index = run_dir / "report" / "index.html"
    html, links = referenced(index)
    assert links and all(not re.match(r"[a-z]+://", link) for link in links)  # no network, no CDN
    assert all((index.parent / link).is_file() for link in links)
    for heading in ("Leaderboard, task denoise", "Time against error, task denoise", "Pareto front",
                    "Best within a frame budget", "synthetic-moving (denoise)", "Per-pixel error",
                    "per frame", "Skipped and errored jobs", "machine", "seeds"):
        assert heading in html, heading
    assert 'class="sortable"' in html and "sortTable" in html
    names = {link.rsplit("/", 1)[-1] for link in links}
    assert "time-denoise-display_rmse-overall.png" in names
    assert any(n.startswith("denoise-synthetic-moving-") and "crop" in n for n in names)
    assert any("relmse" in n for n in names) and any("strip" in n for n in names)
    assert any("flip" in n for n in names) and any("frames-denoise" in n for n in names)
    # error and flicker over the frames: two panels (per-frame temporal_error below the error)
    assert "temporal_error_per_frame per frame" in html and "Flicker (temporal_error over the sequence" in html
    from PIL import Image

    assert Image.open(index.parent / "img" / "frames-denoise-synthetic-moving.png").size == (750, 620)
    # the frames kept for the report: three per job of the first seed, with the input and reference
    kept = sorted(p.name for p in (run_dir / "report-frames" / "denoise" / "synthetic-moving").glob("*.npy"))
    assert {f"reference-f{t}.npy" for t in kept_frames(3)} <= set(kept)
    assert {"input-spp1-f2.npy", "input-spp2-f2.npy"} <= set(kept)
    assert len(kept) == 3 * (3 + 2 * 3)  # frames x (reference, 2 inputs, 3 configurations at 2 spp)


@pytest.mark.slow
def test_report_command_rebuilds_with_budgets_and_metrics_and_without_frames(run_dir, tmp_path):
    out = bench(["report", run_dir, "--out", tmp_path / "r", "--budget", "5,50", "--plot-metrics",
                 "display_rmse,ssim"])
    assert "report written to" in out.stdout
    html, links = referenced(tmp_path / "r" / "index.html")
    assert all((tmp_path / "r" / link).is_file() for link in links)
    assert "time-denoise-ssim-overall.png" in html and "50" in html
    bare = tmp_path / "bare"
    shutil.copytree(run_dir, bare, ignore=shutil.ignore_patterns("report-frames", "report"))
    bench(["report", bare])
    assert "run with <code>--report</code>" in (bare / "report" / "index.html").read_text()
    missing = bench(["report", tmp_path / "nothing"], check=False)
    assert missing.returncode == 2 and missing.stdout == ""


@pytest.mark.slow
def test_report_opens_in_a_headless_browser(run_dir, tmp_path):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("chromium is not installed (Debian: apt-get install -y chromium; .ci/run installs it)")
    from PIL import Image

    shot = tmp_path / "shot.png"
    index = run_dir / "report" / "index.html"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1280,1600", f"--screenshot={shot}",
                    index.as_uri()], capture_output=True, timeout=120, check=True)
    pixels = np.asarray(Image.open(shot).convert("L"), np.float64)
    assert pixels.shape == (1600, 1280)
    assert pixels.std() > 10  # not blank
    assert (pixels < 128).mean() > 0.01  # text, tables and plots drawn, not a white page


def test_crops_go_where_the_filters_disagree_most():
    base = np.full((64, 96, 3), 0.2, np.float32)
    other = base.copy()
    other[40:52, 60:72] = 0.9  # disagreement here
    other[5:8, 5:8] = 0.3  # a small one here
    windows = pictures.disagreement_crops([base, other], count=2, size=16)
    top, left, size = windows[0]
    assert size == 16 and top <= 40 and top + size >= 52 and left <= 60 and left + size >= 72
    t2, l2, _ = windows[1]
    assert not (abs(t2 - top) < size and abs(l2 - left) < size)  # windows do not overlap
    assert pictures.crop(other, windows[0], scale=2).shape == (32, 32, 3)
    framed = pictures.outline(base, windows)
    assert framed[top, left].max() > 1 and np.array_equal(framed[top + 1:top + size - 1, left + 1:left + size - 1],
                                                          base[top + 1:top + size - 1, left + 1:left + size - 1])


def test_relmse_map_and_html_helpers():
    ref = np.ones((4, 4, 3), np.float32)
    assert np.allclose(pictures.relmse_map(ref * 2, ref), 1 / 1.01)
    import pandas as pd

    html = table(pd.DataFrame({"a<b": ["<script>", 1.5], "n": [float("nan"), 2.0]}))
    assert "&lt;script&gt;" in html and "<script>" not in html and "-" in html
    assert safe_name("eaw/cpu iterations=3 @2spp") == "eaw_cpu_iterations=3_2spp"


def test_the_report_ranks_each_tier_and_states_their_agreement():
    """A table of both tiers: one leaderboard section per tier (its scenes named), then Kendall's tau."""
    from types import SimpleNamespace

    from harness.report.build import _leaderboards
    from harness.results import leaderboard
    from harness.rows import make_table
    from tests.test_leaderboard import SPECS, tiered

    table = make_table(tiered({"a": 0.1, "b": 0.2, "c": 0.3}, "procedural", ("p1",))
                       + tiered({"a": 0.3, "b": 0.2, "c": 0.4}, "real", ("r1",)))
    html = "".join(_leaderboards(table, SimpleNamespace(metrics=SPECS), leaderboard(table, SPECS), None))
    assert "Leaderboard, task denoise, tier procedural (p1)" in html and "tier real (r1)" in html
    assert "Rank agreement between the tiers" in html and "procedural vs real" in html
    # a: 1st then 2nd, b: 2nd then 1st, c: 3rd on both: one pair of three reversed, tau = 1/3
    assert "0.3333" in html
    single = make_table(tiered({"a": 0.1, "b": 0.2}, "procedural", ("p1",)))
    alone = "".join(_leaderboards(single, SimpleNamespace(metrics=SPECS), leaderboard(single, SPECS), None))
    assert "Leaderboard, task denoise</h2>" in alone and "Rank agreement" not in alone
