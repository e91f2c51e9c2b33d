"""`denoise-bench stress`: the battery, its properties, fuzzing with shrinking, replay, storage, the CLI."""

import json
import types

import numpy as np
import pandas as pd
import pytest

import harness.memory
from harness import FilterSpec, hookimpl, load_plugins
from harness.buffers import CHANNELS, Frame
from harness.cli import main
from harness.executors import InlineExecutor
from harness.stress import CASES, Sequence, load_reproducer, make_targets, read_stress, run_stress, select_cases
from harness.stress.cases import STATIC_FRAMES, exemption
from harness.stress.check import run_case, run_sequence
from harness.stress.frames import flat_frame, scene_frame, with_color
from harness.stress.properties import Monitor
from harness.testing import checks, plugin_checks
from harness.testing.stress import StressCheck
from harness.timer import time_frame
from tests.conftest import bench_env
from tests.test_run import bench


# ------------------------------------------------------------------ fake filters, built in the test process
class Copy:
    """Returns the colour (or direct + indirect where it reads them)."""

    def __init__(self, backend="cpu"):
        pass

    def reset(self):
        pass

    def __call__(self, frame, sampler=None):
        if "direct" in frame:
            return (frame["direct"] + frame["indirect"]).astype(np.float32)
        return np.array(frame["color"], np.float32)


class Scale(Copy):
    """Multiplies the colour by a factor (not a convex combination unless the factor is 1)."""

    factor = 1.5

    def __call__(self, frame, sampler=None):
        return (frame["color"] * np.float32(self.factor)).astype(np.float32)


class Average:
    """A temporal filter: exponential average of the colour; ``honour_cuts`` drops history at a camera cut."""

    def __init__(self, backend="cpu", alpha=0.2, honour_cuts=True, drift=0.0, reset_clears=True):
        self.alpha, self.honour_cuts, self.drift, self.reset_clears = alpha, honour_cuts, drift, reset_clears
        self.history, self.calls = None, 0

    def reset(self):
        if self.reset_clears:
            self.history, self.calls = None, 0

    def __call__(self, frame, sampler=None):
        color = frame["color"].astype(np.float64)
        cut = frame.meta.camera_cut and self.honour_cuts
        if self.history is None or cut or self.history.shape != color.shape:
            self.history = color
        else:
            self.history = (1 - self.alpha) * self.history + self.alpha * color
        self.calls += 1
        return (self.history * (1 + self.drift * self.calls)).astype(np.float32)


def spec_of(factory, **declared) -> FilterSpec:
    return FilterSpec(name=declared.pop("name", "fake"), version="0", factory=factory, **declared)


def run(spec, case_name):
    return run_case(spec, "cpu", dict(spec.params), CASES[case_name])


# ------------------------------------------------------------------ the battery as data
def test_the_battery_covers_the_issue_and_builds_only_declared_channels():
    names = set(CASES)
    for needed in ["fireflies-1e3", "fireflies-1e8", "color-float-max", "color-negative-zero", "color-dynamic-range",
                   "color-denormal", "color-zero", "color-constant", "color-negative", "guide-normal-nan",
                   "guide-depth-inf", "guide-depth-zero", "guide-albedo-zero", "guide-normal-zero",
                   "guide-motion-outside", "guide-object_id-minus-one", "shape-1x1", "shape-1x33", "shape-33x1",
                   "shape-7x5", "shape-4k", "sequence-static-1000", "sequence-camera-cuts",
                   "sequence-resolutions", "repair-scattered", "repair-everything"]:
        assert needed in names
    guides = [c for c in CHANNELS if c not in ("color", "direct", "indirect", "emission", "object_id", "spp")]
    for channel in guides:
        assert {f"guide-{channel}-{v}" for v in ("nan", "inf", "neginf", "max")} <= names, channel
    spec = spec_of(Copy, requires={"color", "normal", "depth"}, optional={"direct", "indirect"}, temporal=True)
    for case in select_cases(heavy=False):
        if case.skip_reason(spec):
            continue
        sequence = case.sequence(spec)
        for frame in sequence:
            assert frame.channels == {"color", "normal", "depth", "direct", "indirect"}, case.name
            if case.group == "policy":
                continue  # garbage repaired channel by channel: direct + indirect is not the colour
            with np.errstate(over="ignore", invalid="ignore"):  # 3.4e38 * 0.6 + 3.4e38 * 0.4 may round up
                total = frame["direct"].astype(np.float64) + frame["indirect"]
            np.testing.assert_allclose(total, frame["color"], rtol=1e-6, atol=0, err_msg=case.name)
        assert len(sequence) >= 3 or case.group == "sequence", f"{case.name}: temporal filters get 3 frames"


def test_cases_apply_to_filters_that_read_their_channel_or_keep_history():
    spatial = spec_of(Copy, requires={"color", "normal"})
    assert CASES["guide-normal-nan"].skip_reason(spatial) is None
    assert CASES["guide-albedo-nan"].skip_reason(spatial) == "the filter does not read 'albedo'"
    assert CASES["sequence-static-1000"].skip_reason(spatial) == "the filter keeps no history"
    assert CASES["shape-1x1"].skip_reason(spatial) is None


def test_case_selection_by_name_group_and_pattern():
    assert [c.name for c in select_cases(["shape-1x1"])] == ["shape-1x1"]
    assert {c.group for c in select_cases(["policy"])} == {"policy"}
    assert {c.name for c in select_cases(["guide-normal-*"])} == {
        "guide-normal-nan", "guide-normal-inf", "guide-normal-neginf", "guide-normal-max", "guide-normal-zero",
        "guide-normal-nan-all"}
    assert not any(c.heavy for c in select_cases(heavy=False))
    assert select_cases(["light"]) == select_cases(heavy=False) and select_cases(["all"]) == list(CASES.values())
    with pytest.raises(ValueError, match=r"no stress case matches 'nope' \(.*a group: colour, guide.*'all'\)$"):
        select_cases(["nope"])
    with pytest.raises(ValueError, match="did you mean shape-4k"):
        select_cases(["shape-4K"])


def test_repaired_frames_hold_only_safe_values():
    spec = spec_of(Copy, requires=set(CHANNELS) - {"direct", "indirect"})
    for name in ("repair-scattered", "repair-everything"):
        frame = next(iter(CASES[name].sequence(spec)))
        for channel in frame.channels:
            values = frame[channel]
            if channel == "depth":
                assert not np.isnan(values).any() and (values >= 0).all()
            elif values.dtype.kind == "f":
                assert np.isfinite(values).all() and np.abs(values).max() <= 1e30, channel
        assert frame["color"].min() >= 0


# ------------------------------------------------------------------ properties: each can fail
def test_a_copy_passes_everything_light_and_declared_convex():
    spec = spec_of(Copy, requires=set(CHANNELS) - {"direct", "indirect"}, convex=True)
    for case in select_cases(heavy=False):
        if not case.skip_reason(spec):
            result = run_case(spec, "cpu", {}, case)
            assert result.status == "pass", (case.name, result)


def test_non_finite_output_on_finite_input_is_found_where_it_is():
    class NanAtGuide(Copy):
        def __call__(self, frame, sampler=None):
            return (frame["color"] * frame["normal"]).astype(np.float32)  # a NaN normal leaks

    result = run(spec_of(NanAtGuide, requires={"color", "normal"}), "guide-normal-nan")
    assert result.status == "nonfinite" and result.frame == 0
    assert "where the input radiance is finite" in result.message


def test_a_convex_filter_must_stay_in_the_input_range_and_others_within_the_gain_bound():
    scale = spec_of(Scale)
    assert run(scale, "fireflies-1e3").status == "pass"  # 1.5x is within the gain bound of a non-convex filter
    result = run(spec_of(Scale, convex=True), "fireflies-1e3")
    assert result.status == "out_of_bounds" and "outside the input range" in result.message

    class Blowup(Scale):
        factor = 1e4

    result = run(spec_of(Blowup), "fireflies-1e3")
    assert result.status == "out_of_bounds" and "exceeds 1000 x the largest input" in result.message


class Demodulate(Copy):
    """Demodulates by ``max(albedo, 1e-3)``, blurs over the whole frame and remodulates: what SVGF
    did on a zero-albedo conductor before issue 32."""

    def __call__(self, frame, sampler=None):
        albedo = np.maximum(frame["albedo"].astype(np.float64), 1e-3)
        irradiance = (frame["color"] / albedo).mean(axis=(0, 1))
        return (albedo * irradiance).astype(np.float32)


def test_the_local_range_property_catches_an_amplifying_demodulation():
    spec = spec_of(Demodulate, requires={"color", "albedo"})
    assert run(spec, "fireflies-1e3").status == "pass"  # ordinary albedo: within 4x of the input
    result = run(spec, "guide-albedo-conductor")
    assert result.status == "out_of_bounds" and "4 x the largest input magnitude within the frame" in result.message
    assert run(spec_of(Demodulate, requires={"color", "albedo"}, range_gain=1e6), "guide-albedo-conductor").status \
        == "pass"


def test_a_declared_window_makes_the_range_local():
    class Shift(Copy):
        """Moves the image by 5 columns: within the frame's range, not within 2 pixels'."""

        def __call__(self, frame, sampler=None):
            color = frame["color"]
            return np.concatenate([np.repeat(color[:, :1], 5, axis=1), color[:, :-5]], axis=1).astype(np.float32)

    assert run(spec_of(Shift), "fireflies-1e3").status == "pass"
    result = run(spec_of(Shift, range_radius=2), "fireflies-1e3")
    assert result.status == "out_of_bounds" and "within 2 pixels" in result.message
    assert run(spec_of(Shift, range_radius=5, range_gain=1.0), "fireflies-1e3").status == "pass"


def test_window_max_is_the_largest_value_of_each_square():
    from harness.stress.properties import window_max

    values = np.random.default_rng(0).normal(size=(7, 9))
    got = window_max(values, 2)
    for i in range(7):
        for j in range(9):
            assert got[i, j] == values[max(i - 2, 0):i + 3, max(j - 2, 0):j + 3].max()
    with pytest.raises(ValueError, match="range_gain"):
        spec_of(Copy, range_gain=0.5)
    with pytest.raises(ValueError, match="range_radius"):
        spec_of(Copy, range_radius=-1)


def test_a_filter_that_shifts_a_flat_image_fails_the_mean_property():
    class Bias(Copy):
        def __call__(self, frame, sampler=None):
            return (frame["color"] + np.float32(0.01)).astype(np.float32)

    assert run(spec_of(Bias), "color-constant").status == "mean_shift"
    assert run(spec_of(Bias), "fireflies-1e3").status == "pass"  # not flat: no mean property


def test_history_must_not_leak_across_a_camera_cut():
    honest = spec_of(Average, temporal=True, convex=True)
    leaky = spec_of(lambda backend="cpu": Average(honour_cuts=False), temporal=True)
    assert run(honest, "sequence-camera-cuts").status == "pass"
    result = run(leaky, "sequence-camera-cuts")
    assert result.status == "mean_shift" and result.frame == 3  # the first frame after the cut


def test_reset_must_give_a_fresh_instance():
    counting = spec_of(lambda backend="cpu": Average(drift=0.01), temporal=True)
    stale = spec_of(lambda backend="cpu": Average(drift=0.01, reset_clears=False), temporal=True)
    assert run(counting, "sequence-resolutions").status == "pass"
    result = run(stale, "sequence-resolutions")
    assert result.status == "reset_differs" and result.frame == 2  # the first reset


@pytest.mark.slow
def test_energy_of_a_long_static_sequence_is_bounded_and_does_not_drift():
    assert STATIC_FRAMES == 1000
    steady = run(spec_of(Average, temporal=True), "sequence-static-1000")
    assert steady.status == "pass" and steady.calls == 1000 and "energy ratio" in steady.notes
    drifting = spec_of(lambda backend="cpu": Average(drift=1e-4), temporal=True)
    result = run(drifting, "sequence-static-1000")
    assert result.status == "unstable" and "drifts" in result.message  # +10% over 1000 frames: inside 1 +- 0.2
    exploding = spec_of(lambda backend="cpu": Average(drift=1e-3), temporal=True)
    assert run(exploding, "sequence-static-1000").status == "unstable"


@pytest.mark.parametrize("resident", ["measured", "unmeasurable"])
def test_a_call_that_allocates_per_pixel_windows_fails_the_memory_bound(resident, monkeypatch, tmp_path):
    """Where the resident size's high-water mark cannot be reset (a container), the traced peak holds the bound."""
    if resident == "unmeasurable":
        monkeypatch.setattr(harness.memory, "_CLEAR_REFS", tmp_path / "absent" / "clear_refs")

    class Hog(Copy):
        def __call__(self, frame, sampler=None):
            window = np.ones((frame.height * frame.width, 400), np.float32)  # 1,600 bytes per pixel
            return (np.array(frame["color"]) + window[:, :3].reshape(frame.shape + (3,)) * 0).astype(np.float32)

    sequence = Sequence.of([scene_frame(256, 256, {"color"})])
    result = run_sequence(spec_of(Hog), "cpu", {}, sequence, memory_bound=True)
    assert result.status == "memory" and "more than 1024 bytes per pixel" in result.message
    assert result.peak_mb >= 90  # 100 MiB allocated
    assert run_sequence(spec_of(Copy), "cpu", {}, sequence, memory_bound=True).status == "pass"


def test_monitor_range_covers_direct_plus_indirect():
    frame = with_color(scene_frame(4, 4, {"direct", "indirect"}), np.full((4, 4, 3), 2.0, np.float32))
    monitor = Monitor(convex=True)
    assert monitor.check(0, frame, np.full((4, 4, 3), 2.0, np.float32)) is None
    assert monitor.check(0, frame, np.full((4, 4, 3), 2.1, np.float32)).status == "out_of_bounds"


def test_invalid_radiance_may_be_rejected_with_a_clear_error_but_nothing_else_may_raise():
    class Strict(Copy):
        def __call__(self, frame, sampler=None):
            if (frame["color"] < 0).any():
                raise ValueError("strict: negative radiance")
            return super().__call__(frame)

    assert run(spec_of(Strict), "color-negative").status == "rejected"

    class Fragile(Copy):
        def __call__(self, frame, sampler=None):
            raise ZeroDivisionError("oops")

    result = run(spec_of(Fragile), "color-negative")
    assert result.status == "error" and "ZeroDivisionError: oops" in result.message


def test_the_first_call_is_checked_like_every_other():
    class NanOnFirstCall(Copy):
        calls = 0

        def __call__(self, frame, sampler=None):
            NanOnFirstCall.calls += 1
            out = super().__call__(frame)
            return out * np.float32(np.nan) if NanOnFirstCall.calls == 1 else out

    spec = spec_of(NanOnFirstCall)
    result = run_sequence(spec, "cpu", {}, Sequence.of([scene_frame(4, 4, {"color"})]))
    assert result.status == "nonfinite" and result.frame == 0
    NanOnFirstCall.calls = 0  # the job runner checks the warm-up call too
    with pytest.raises(ValueError, match="non-finite"):
        time_frame(spec.factory(), spec, "cpu", scene_frame(4, 4, {"color"}), True, 2, check="filter 'fake'")


def test_colour_checks_perturb_direct_and_indirect_too():
    class ReadsSplit(Copy):
        def __call__(self, frame, sampler=None):
            d = frame["direct"]
            with np.errstate(over="ignore", invalid="ignore"):
                return (d * d / (d * d) * (d + frame["indirect"])).astype(np.float32)

    spec = spec_of(ReadsSplit, requires={"color", "direct", "indirect"})
    frame = scene_frame(4, 4, {"direct", "indirect"})
    assert np.isfinite(ReadsSplit()(frame.replace(color=frame["color"] * np.float32(1e30)))).all()  # colour alone
    with pytest.raises(ValueError, match="non-finite"):
        checks.check_huge_values(spec, "cpu")


# ------------------------------------------------------------------ exemptions and the pytest battery
def test_stress_exempt_needs_a_reason_and_matches_names_and_patterns():
    with pytest.raises(ValueError, match="stress_exempt needs a measured reason"):
        spec_of(Copy, stress_exempt={"color-zero": " "})
    spec = spec_of(Copy, stress_exempt={"guide-normal-*": "measured: x", "color-zero": "measured: y"})
    assert exemption(spec, "guide-normal-nan") == "measured: x" and exemption(spec, "color-zero") == "measured: y"
    assert exemption(spec, "color-constant") is None
    assert spec.declarations()["convex"] is False and spec.declarations()["stress_exempt"]["color-zero"]


def test_parametrize_with_checks_gains_the_applicable_stress_cases():
    ids = [item.id for item in plugin_checks(filters=["passthrough"])]
    assert "filter:passthrough[cpu]-stress:shape-1x1" in ids
    assert "filter:passthrough[cpu]-stress:shape-4k" not in ids  # heavy: only with stress="all"
    assert not any("guide-normal" in i for i in ids)  # passthrough reads no normals
    assert "filter:passthrough[cpu]-stress:shape-4k" in [i.id for i in plugin_checks(filters=["passthrough"],
                                                                                     stress="all")]
    assert not any("stress:" in i.id for i in plugin_checks(filters=["passthrough"], stress=None))
    exempt = spec_of(Copy, stress_exempt={"shape-*": "measured"})
    shape = next(i for i in plugin_checks(filters=["passthrough"]) if i.id.endswith("shape-1x1"))
    assert shape.xfail_reason(exempt) == "measured"


def test_the_third_party_example_gets_the_battery_in_its_own_conformance_tests():
    # examples/third_party_filter/tests (in the suite's testpaths) runs these through the pytest plugin
    from harness.testing import registry

    spec = registry().get("filter", "median3")
    assert spec.convex and not spec.stress_exempt
    ids = {item.id for item in plugin_checks(filters=["median3"])}
    expected = {f"filter:median3[cpu]-stress:{c.name}" for c in select_cases(["light"]) if c.skip_reason(spec) is None}
    assert expected <= ids and len(expected) == 24


def test_a_stress_check_in_process_raises_naming_the_case():
    class Nan(Copy):
        def __call__(self, frame, sampler=None):
            return np.full((frame.height, frame.width, 3), np.nan, np.float32)

    with pytest.raises(AssertionError, match=r"stress case 'shape-1x1' \(1x1 pixel\): nonfinite at frame 0"):
        StressCheck(CASES["shape-1x1"], isolate=False)(spec_of(Nan), "cpu")


# ------------------------------------------------------------------ a stress run, stored like a run
def test_a_stress_run_is_stored_with_a_manifest_and_shown(tmp_path, capsys):
    from harness.testing import registry

    reg = registry()
    targets = make_targets(reg, ["passthrough", "gaussian"], ["cpu"])
    out = run_stress(reg, InlineExecutor(reg), tmp_path / "s", targets,
                     cases=select_cases(["shape-1x1", "color-zero", "guide-normal-nan"]))
    df = read_stress(tmp_path / "s")
    assert len(df) == 6 and list(df.columns) == list(out.table.columns)
    assert set(df.verdict) == {"pass", "n/a"} and (df[df.verdict == "n/a"].case == "guide-normal-nan").all()
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["kind"] == "stress" and manifest["verdicts"] == {"pass": 4, "n/a": 2}
    assert manifest["cases"] == ["color-zero", "guide-normal-nan", "shape-1x1"]
    assert set(df[df.verdict == "pass"].command) == {
        f"denoise-bench stress --filters {f} --backend cpu --cases {c}" for f in ("passthrough", "gaussian")
        for c in ("shape-1x1", "color-zero")}
    assert main(["show", str(tmp_path / "s")]) == 0
    shown = capsys.readouterr().out
    assert "passthrough" in shown and "shape-1x1" in shown and "4 pass" in shown


def test_warnings_of_a_case_are_notes_not_output(tmp_path, capfd):
    class Squares(Copy):
        def __call__(self, frame, sampler=None):
            c = frame["color"]
            return np.minimum(c * c, np.float32(1)).astype(np.float32)  # overflows (and warns) at 1e30

    plugin = types.ModuleType("warning_plugin")
    plugin.register_filters = hookimpl(lambda: [spec_of(Squares, name="squares")])
    reg = load_plugins(extra=[plugin], entry_points=False)
    out = run_stress(reg, InlineExecutor(reg), tmp_path / "s", make_targets(reg, ["squares"], ["cpu"]),
                     cases=select_cases(["color-flat-huge", "shape-1x1"]))
    notes = out.table.set_index("case").notes
    assert notes["color-flat-huge"].startswith("1 warning(s): RuntimeWarning: overflow encountered in multiply")
    assert notes["shape-1x1"] == "" and "RuntimeWarning" not in capfd.readouterr().err


def test_rerun_commands_name_the_changed_parameters_or_the_reproducer(tmp_path):
    from harness.stress.run import rerun_command
    from harness.testing import registry

    gaussian, = make_targets(registry(), ["gaussian"], ["cpu"], params={"gaussian": {"sigma": 2.5}})
    assert rerun_command(gaussian, "shape-1x1") == ("denoise-bench stress --filters gaussian --backend cpu "
                                                    "--cases shape-1x1 --param gaussian.sigma=2.5")
    path = str(tmp_path / "my dir" / "gaussian-cpu.npz")
    assert rerun_command(gaussian, "fuzz", path) == f"denoise-bench stress --replay {path}"
    assert rerun_command(gaussian, "replay:x.npz", path) == (
        f"denoise-bench stress --filters gaussian --backend cpu --replay '{path}' --param gaussian.sigma=2.5")


def test_the_cli_runs_the_light_battery_by_default(tmp_path, capsys):
    assert main(["stress", "--filters", "passthrough", "--executor", "inline", "--out", str(tmp_path / "s")]) == 0
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["cases"] == [c.name for c in select_cases(["light"])] and "shape-4k" not in manifest["cases"]
    err = capsys.readouterr().err.splitlines()  # not a terminal: one line per case
    assert err[2].startswith("[1/") and err[-1].endswith("passthrough/cpu stress repair-everything: pass")


def test_declared_failures_and_stale_declarations_have_their_verdicts(tmp_path):
    class Bias(Copy):
        def __call__(self, frame, sampler=None):
            return (frame["color"] + np.float32(0.01)).astype(np.float32)

    plugin = types.ModuleType("declaring_plugin")

    @hookimpl
    def register_filters():
        return [spec_of(Bias, name="biased", stress_exempt={"color-*": "measured: adds 0.01"}),
                spec_of(Copy, name="fine", convex=True, stress_exempt={"shape-1x1": "measured: nothing"})]

    plugin.register_filters = register_filters
    reg = load_plugins(extra=[plugin], entry_points=False)
    targets = make_targets(reg, ["biased", "fine"], ["cpu"])
    out = run_stress(reg, InlineExecutor(reg), tmp_path / "s", targets,
                     cases=select_cases(["color-constant", "shape-1x1"]))
    verdicts = out.table.set_index(["filter", "case"]).verdict.to_dict()
    assert verdicts == {("biased", "color-constant"): "declared", ("biased", "shape-1x1"): "pass",
                        ("fine", "color-constant"): "pass", ("fine", "shape-1x1"): "stale"}
    assert out.manifest["verdicts"] == {"pass": 2, "declared": 1, "stale": 1}


# ------------------------------------------------------------------ through the CLI, in worker processes
FAULTY = """
import ctypes, time
import numpy as np
from harness import FilterSpec, hookimpl

class Faulty:
    def __init__(self, backend="cpu", how="segv"):
        self.how = how
    def reset(self):
        pass
    def __call__(self, frame, sampler=None):
        if np.isnan(frame["normal"]).any():
            if self.how == "segv":
                ctypes.string_at(0)
            time.sleep(10_000)
        return np.array(frame["color"], copy=True)

class Shrink:
    '''Shrinks each pixel towards the image mean by var / (var + 0.01), all in float32.'''
    def __init__(self, backend="cpu"):
        pass
    def reset(self):
        pass
    def __call__(self, frame, sampler=None):
        c = frame["color"]
        with np.errstate(over="ignore", invalid="ignore"):
            mean = c.mean(axis=(0, 1), dtype=np.float32)
            var = (c * c).mean(axis=(0, 1), dtype=np.float32) - mean * mean
            k = var / (var + np.float32(0.01))
            return (mean + k * (c - mean)).astype(np.float32)

@hookimpl
def register_filters():
    faulty = [FilterSpec(name=how, version="0", factory=lambda backend="cpu", how=how: Faulty(backend, how),
                         requires={"color", "normal"}) for how in ("segv", "hang")]
    return faulty + [FilterSpec(name="shrink", version="0", factory=Shrink)]
"""


@pytest.fixture
def faulty(fake_distribution):
    return fake_distribution("stress-faulty-dist", {"stress_faulty": "stress_faulty"}, {"stress_faulty": FAULTY})


@pytest.mark.slow
def test_crashes_and_hangs_are_rows_and_the_run_goes_on(tmp_path, faulty):
    out = bench(["stress", "--filters", "segv,hang,passthrough", "--cases", "guide-normal-nan,shape-1x1",
                 "--timeout", "5", "--out", tmp_path / "s", "--markdown", tmp_path / "md" / "s.md"],
                env=bench_env(faulty), check=False)
    assert out.returncode == 1, out.stderr
    assert "[1/5] segv/cpu stress guide-normal-nan: crash (fail): the worker process died" in out.stderr
    rerun = "rerun: denoise-bench stress --filters hang --backend cpu --cases guide-normal-nan"
    assert rerun in out.stdout and rerun in (tmp_path / "md" / "s.md").read_text()
    df = pd.read_parquet(tmp_path / "s" / "results.parquet").set_index(["filter", "case"])
    assert df.loc[("segv", "guide-normal-nan"), "status"] == "crash"
    assert "SIGSEGV (segmentation fault)" in df.loc[("segv", "guide-normal-nan"), "message"]
    assert df.loc[("hang", "guide-normal-nan"), "status"] == "timeout"
    assert df.loc[("segv", "shape-1x1"), "status"] == df.loc[("hang", "shape-1x1"), "status"] == "pass"
    assert df.loc[("passthrough", "guide-normal-nan"), "verdict"] == "n/a"
    assert "CRASH" in out.stdout and "timeout" in out.stdout


@pytest.mark.slow
def test_a_crashing_stress_check_fails_its_test_not_the_session(faulty, monkeypatch):
    import harness.testing.stress
    from harness.testing import registry

    monkeypatch.setattr(harness.testing.stress, "_executor", None)  # a worker that sees the fake distribution
    registry.cache_clear()
    try:
        with pytest.raises(AssertionError, match="crash at frame 0: the worker process died: SIGSEGV"):
            StressCheck(CASES["guide-normal-nan"])(registry().get("filter", "segv"), "cpu")
    finally:
        registry.cache_clear()


@pytest.mark.slow
def test_fuzzing_finds_shrinks_saves_and_replays_a_third_party_failure(tmp_path, faulty, capsys):
    import importlib

    shrink = importlib.import_module("stress_faulty").Shrink()
    frame = scene_frame(7, 5, {"color"})
    color = np.array(frame["color"])
    color[3, 2] = 1e30
    assert np.isnan(shrink(with_color(frame, color))).any()  # the reported failure: 7x5, one 1e30 pixel
    assert np.isfinite(shrink(frame)).all()

    out = bench(["stress", "--filters", "shrink", "--fuzz", "200", "--quiet", "--out", tmp_path / "s"],
                env=bench_env(faulty), check=False)
    assert out.returncode == 1, out.stderr
    row = pd.read_parquet(tmp_path / "s" / "results.parquet").iloc[0]
    assert row.case == "fuzz" and row.status == "nonfinite" and row.verdict == "fail"
    path = tmp_path / "s" / "reproducers" / "shrink-cpu.npz"
    assert row.reproducer == str(path) and f"denoise-bench stress --replay {path}" in out.stdout
    frames, info = load_reproducer(path)
    assert len(frames) == 1 and frames[0].height * frames[0].width <= 4  # shrunk from up to 8x8
    assert info["filter"] == "shrink" and info["command"] == f"denoise-bench stress --replay {path}"
    assert frames[0]["color"].max() >= 1.8e19  # c * c overflows float32 from 2**64 on

    again = bench(["stress", "--replay", path, "--quiet", "--out", tmp_path / "r"], env=bench_env(faulty), check=False)
    assert again.returncode == 1, again.stderr
    replayed = pd.read_parquet(tmp_path / "r" / "results.parquet").iloc[0]
    assert replayed.case == "replay:shrink-cpu.npz" and replayed.status == "nonfinite"
    fixed = bench(["stress", "--replay", path, "--filters", "passthrough", "--quiet", "--out", tmp_path / "p"],
                  env=bench_env(faulty))
    assert "replay:shrink-cpu.npz" in fixed.stdout and "1 pass" in fixed.stdout


@pytest.mark.parametrize("args, message", [
    (["--fuzz", "0"], "argument --fuzz: must be >= 1, got 0"),
    (["--fuzz", "many"], "argument --fuzz: must be an integer, got 'many'"),
    (["--replay", "no-such.npz"], "argument --replay: no reproducer file 'no-such.npz'"),
    (["--backend", "tpu"], "argument --backend: must be among cpu, cuda, auto, all, got tpu"),
    (["--timeout", "0"], "argument --timeout: must be a finite number of seconds > 0"),
    (["--cases", "nope"], "no stress case matches 'nope'"),
    (["--filters", "nope"], "no filter named 'nope'"),
    (["--filters", "gaussian", "--param", "gaussian.sigma=-1"], "filter 'gaussian': parameter 'sigma'"),
    (["--filters", "gaussian", "--param", "eaw.iterations=2"], "parameters or a preset for filter 'eaw'"),
    (["--filters", "gaussian", "--workers", "2"], "--scheduler and --workers need --executor dask"),
    (["--cases", "shape-4K"], "did you mean shape-4k"),
])
def test_bad_stress_options_are_one_line_errors_with_exit_2(args, message, tmp_path, capsys):
    try:
        code = main(["stress", *args, "--out", str(tmp_path / "s")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "s").exists()


def test_a_file_that_is_not_a_reproducer_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_text("not a zip")
    assert main(["stress", "--replay", str(bad), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "bad.npz is not a stress reproducer: not an .npz archive" in err and len(err.strip().splitlines()) == 1


def test_reproducers_store_frames_bit_for_bit(tmp_path):
    from harness.stress import save_reproducer

    frames = [flat_frame(2, 3, {"normal", "object_id"}, level=-0.0, index=t) for t in range(2)]
    save_reproducer(tmp_path / "r.npz", frames, {"filter": "x", "resets": [1]})
    loaded, info = load_reproducer(tmp_path / "r.npz")
    assert info["resets"] == [1] and info["frames"] == 2
    for a, b in zip(frames, loaded):
        assert isinstance(b, Frame) and b.meta.to_dict() == a.meta.to_dict()
        for name in a.channels:
            assert a[name].tobytes() == b[name].tobytes()
