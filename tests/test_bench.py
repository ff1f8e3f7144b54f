"""`volsr bench`: quality against time on the phantom at a tiny size, the Pareto front, the targets."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from volsr_core.apps.bench.report import check_targets, curve_psnr_at, curve_time_for, pareto_front, target_lines
from volsr_core.apps.bench.scenes import parse_volume_spec as parse_scene_spec
from volsr_core.temporal.resample import resize_bilinear, upscale_bilinear

SPP, FACTORS, SCALES = [1, 4], [2, 3, 4, 6, 8], [2, 4, 8]


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory, model):
    """One small run through the CLI: phantom, 64², 4 frames (1 warm-up), 8-spp reference, a models folder holding a
    copy of the shipped S 4x."""
    import shutil

    pytest.importorskip("skimage")
    pytest.importorskip("matplotlib")
    from volsr_core.cli import main

    root = tmp_path_factory.mktemp("bench")
    models = root / "models"
    models.mkdir()
    shutil.copy(model, models / "s4.onnx")
    out = root / "out"
    status = main(["bench", "--size", "64", "--frames", "4", "--warmup", "1", "--reference-spp", "8",
                   "--spp", ",".join(map(str, SPP)), "--models-dir", str(models), "--out", str(out)])
    assert status == 0
    return out, json.loads((out / "bench.json").read_text())


def by_label(results):
    return {r["label"]: r for r in results["rows"]}


def test_every_method_is_measured_with_finite_numbers(bench_run):
    _, results = bench_run
    rows = by_label(results)
    expected = ({f"native {n} spp" for n in SPP} | {f"native 1/{f} size + bilinear" for f in FACTORS}
                | {f"TAAU {s}x" for s in SCALES} | {"VolSR S 4x in 2 slabs", "VolSR S 4x in 2 slabs + bicubic 2x"})
    assert set(rows) == expected
    assert {r["scene"] for r in rows.values()} == {"phantom, CT-Phantom on -1024..3071 (auto)"}
    for r in rows.values():
        for key in ("ms_render", "ms_network", "ms_total", "psnr", "ssim"):
            assert r[key] is not None and math.isfinite(r[key]), (r["label"], key)
        assert r["ms_render"] > 0 and r["ms_total"] > 0 and 0 < r["ssim"] <= 1
        assert len(r["psnr_frames"]) == 3  # 4 frames, 1 warm-up
        # timed in 3 passes by default (the scored one and two more): 3 frames each, the medians over all 9
        assert len(r["ms_total_frames"]) == 9 and len(r["ms_total_passes"]) == 3, r["label"]
        assert r["ms_total"] == pytest.approx(float(np.median(r["ms_total_frames"])), abs=1e-3)
        assert r["ms_total_passes"] == pytest.approx([float(np.median(r["ms_total_frames"][3 * p:3 * p + 3]))
                                                      for p in range(3)], abs=1e-3)
        assert (r["ms_network"] == 0) == (r["method"] == "native")
    volsr = rows["VolSR S 4x in 2 slabs"]  # scale, variant and slabs came from the ONNX metadata
    assert (volsr["method"], volsr["variant"], volsr["scale"], volsr["model"]) == ("volsr", "S", 4, "s4.onnx")
    assert (volsr["slabs"], volsr["stretch"]) == (2, 1)  # the slabs the shipped S 4x was trained on
    stretched = rows["VolSR S 4x in 2 slabs + bicubic 2x"]  # --stretch 2 by default: the 4x model stretched, 8x
    assert (stretched["scale"], stretched["stretch"], stretched["model"]) == (8, 2, "s4.onnx")
    assert results["settings"]["stretches"] == [2]
    assert results["settings"]["onnxruntime_threads"] == 2 and results["settings"]["measured_frames"] == 3
    assert results["settings"]["timing_passes"] == 3 and results["settings"]["timed_frames"] == 9


def test_quality_orders_as_expected(bench_run):
    # the renderer is deterministic, so these hold whatever the machine's load
    _, results = bench_run
    psnr = {label: r["psnr"] for label, r in by_label(results).items()}
    assert psnr["native 4 spp"] > psnr["native 1 spp"] + 2.0
    assert psnr["native 1 spp"] > psnr["native 1/2 size + bilinear"] > psnr["native 1/8 size + bilinear"]
    assert psnr["TAAU 2x"] > psnr["native 1/2 size + bilinear"]  # accumulating jittered frames beats one LR frame


def test_reports_and_target_verdicts(bench_run):
    out, results = bench_run
    md = (out / "bench.md").read_text()
    assert "## phantom, CT-Phantom" in md and "| VolSR S 4x in 2 slabs |" in md and "| native 1 spp |" in md
    assert "after 1 warm-up frames" in md and "8-spp" in md
    assert "in 3 passes over the orbit (9 frames a method" in md
    s4 = by_label(results)["VolSR S 4x in 2 slabs"]  # each pass's median in its own column
    each = " / ".join(f"{v:.1f}" for v in s4["ms_total_passes"])
    times = f"{s4['ms_render']:.1f} | {s4['ms_network']:.1f} | {s4['ms_total']:.1f} | {each}"
    assert f"| VolSR S 4x in 2 slabs | {times} |" in md
    assert "| VolSR S 4x in 2 slabs + bicubic 2x |" in md and "the model's image at 1/K of the size, stretched" in md
    assert "1. VolSR at 4x reaches at least native 1-spp PSNR" in md and "2. Every VolSR point lies at least" in md
    from PIL import Image

    with Image.open(out / "bench.png") as png:
        assert png.format == "PNG" and png.size[0] > 300
    assert not list(out.glob(".*")), "no temporary files may remain"
    # the verdicts, worked out here from the run's own rows by the targets' definitions (docs/performance.md)
    rows = by_label(results)
    native, volsr = rows["native 1 spp"], rows["VolSR S 4x in 2 slabs"]
    fast = volsr["psnr"] >= native["psnr"] and volsr["ms_total"] <= native["ms_total"] / 2
    curve = sorted((r["ms_total"], r["psnr"]) for r in rows.values() if r["method"] == "bilinear" or r is native)
    on_curve = float(np.interp(volsr["ms_total"], [t for t, _ in curve], [p for _, p in curve]))
    targets = results["targets"]["phantom, CT-Phantom on -1024..3071 (auto)"]
    assert targets["fast_4x"]["met"] is fast
    assert targets["above_bilinear"]["met"] is (volsr["psnr"] >= on_curve + 0.5)
    assert targets["above_bilinear"]["points"][0]["curve_psnr"] == pytest.approx(on_curve, abs=1e-3)
    verdict = {True: "**met**", False: "**not met**"}
    assert f"in ≤ 1/2 of its time: {verdict[fast]}" in md
    assert f"at equal time: {verdict[volsr['psnr'] >= on_curve + 0.5]}" in md
    cpu = results["machine"]["cpu"]  # the networks' speed depends on the vector instructions: the report says them
    assert cpu is None or f"CPUs ({cpu})," in md


@pytest.mark.parametrize("flags, expected", [("fpu sse2 avx avx2 fma", "AVX2"),
                                             ("avx2 avx512f avx512bw avx512_vnni", "AVX-512 VNNI"),
                                             ("avx2 avx512f", "AVX-512"), ("fpu sse2", "no AVX")])
def test_the_machine_line_names_the_cpu_and_its_vector_instructions(tmp_path, flags, expected):
    from volsr_core.apps.bench.run import cpu_description

    info = tmp_path / "cpuinfo"
    info.write_text(f"processor\t: 0\nmodel name\t: AMD  EPYC 9554\nflags\t\t: {flags}\n\n"
                    f"processor\t: 1\nmodel name\t: AMD  EPYC 9554\nflags\t\t: {flags}\n")
    assert cpu_description(str(info)) == f"AMD EPYC 9554, {expected}"
    assert cpu_description(str(tmp_path / "absent")) is None


def test_pareto_front_on_hand_made_points():
    times = [10, 20, 5, 30, 20, 40, 15, 40]
    psnrs = [25, 30, 20, 29, 28, 35, 25, 35]
    # 10/25 beats 15/25 (same PSNR, less time); 20/30 beats 30/29 and 20/28; the two 40/35 are equal
    assert pareto_front(times, psnrs) == [2, 0, 1, 5, 7]
    assert pareto_front([1.0], [1.0]) == [0]
    assert pareto_front([], []) == []


def test_curve_interpolates_linearly_in_time_and_holds_its_ends():
    times, psnrs = [40.0, 10.0, 20.0], [30.0, 20.0, 22.0]  # any order
    assert curve_psnr_at(times, psnrs, 15.0) == pytest.approx(21.0)
    assert curve_psnr_at(times, psnrs, 30.0) == pytest.approx(26.0)
    assert curve_psnr_at(times, psnrs, 5.0) == 20.0 and curve_psnr_at(times, psnrs, 50.0) == 30.0


def test_curve_time_for_a_psnr_inverts_the_curve():
    times, psnrs = [40.0, 10.0, 20.0], [30.0, 20.0, 22.0]  # any order, as curve_psnr_at
    for at in (10.0, 15.0, 20.0, 33.0, 40.0):
        assert curve_time_for(times, psnrs, curve_psnr_at(times, psnrs, at)) == pytest.approx(at)
    assert curve_time_for(times, psnrs, 19.0) is None  # the curve starts above it: at no time
    assert curve_time_for(times, psnrs, 31.0) == math.inf  # never reaches it: at any time
    # not rising: the first time it reaches the PSNR (the later dip does not count)
    assert curve_time_for([0.0, 10.0, 20.0, 30.0], [20.0, 24.0, 21.0, 26.0], 22.0) == pytest.approx(5.0)


def row(method, label, ms, psnr, scale=1, spp=1):
    return {"scene": "v", "method": method, "label": label, "ms_total": ms, "psnr": psnr, "scale": scale, "spp": spp}


def test_targets_from_hand_made_rows():
    base = [row("native", "native 1 spp", 90.0, 30.0), row("native", "native 4 spp", 360.0, 36.0, spp=4),
            row("bilinear", "1/2", 30.0, 26.0, 2), row("bilinear", "1/4", 10.0, 22.0, 4)]
    good = row("volsr", "VolSR S 4x", 25.0, 31.0, 4)  # in a third of native's 90 ms
    half = row("volsr", "VolSR M 4x", 40.0, 33.0, 4)  # in half, not in a third
    slow = row("volsr", "VolSR L 4x", 50.0, 33.0, 4)  # over half
    weak = row("volsr", "VolSR S 8x", 20.0, 24.0, 8)  # curve at 20 ms: 24 dB; not 0.5 dB above it
    t = check_targets(base + [good, half, slow])["v"]
    assert t["fast_4x"]["met"] is True and t["fast_4x"]["budget_ms"] == pytest.approx(45.0)
    assert [p["met"] for p in t["fast_4x"]["points"]] == [True, True, False]  # L is too slow for the budget
    assert [p["within_third"] for p in t["fast_4x"]["points"]] == [True, False, False]
    assert t["above_bilinear"]["met"] is True
    assert t["above_bilinear"]["points"][1]["curve_psnr"] == pytest.approx(30.0 - 4.0 * 50 / 60, abs=1e-3)
    t = check_targets(base + [slow, weak])["v"]
    assert t["fast_4x"]["met"] is False and t["above_bilinear"]["met"] is False
    assert t["above_bilinear"]["points"][1]["margin_db"] == pytest.approx(0.0)
    # 24 dB would be 0.5 above the curve where it is at 23.5 dB: 17.5 ms, 2.5 ms sooner than the point's 20
    assert t["above_bilinear"]["points"][1]["ms_needed"] == pytest.approx(17.5)
    assert "ms_needed" not in t["above_bilinear"]["points"][0], "a point that meets the margin needs nothing"
    lines = target_lines(t)
    assert lines[-1].endswith("(+0.00 dB): no (at its PSNR it needs ≤ 17.5 ms: 2.5 ms less)")
    hopeless = row("volsr", "VolSR S 8x", 20.0, 21.0, 8)  # below even the fastest bilinear point less the margin
    p = check_targets(base + [hopeless])["v"]["above_bilinear"]["points"][0]
    assert p["ms_needed"] is None and "at no time: the curve's fastest point is above 20.50 dB" in target_lines(
        check_targets(base + [hopeless])["v"])[-1]
    fast = row("volsr", "VolSR S 4x", 5.0, 25.0, 4)  # faster than the whole curve: compared with its end
    p = check_targets(base + [fast])["v"]["above_bilinear"]["points"][0]
    assert p["outside"] and p["curve_psnr"] == 22.0 and p["met"]
    t = check_targets(base)["v"]
    assert t["fast_4x"]["met"] is None and t["above_bilinear"]["met"] is None


def test_targets_at_their_boundaries_and_per_scene():
    """Equal PSNR at exactly half the time meets target 1; a point exactly 0.5 dB above the curve meets
    target 2, one just under it does not."""
    base = [row("native", "native 1 spp", 90.0, 30.0), row("bilinear", "1/2", 30.0, 26.0, 2),
            row("bilinear", "1/4", 10.0, 22.0, 4)]
    edge = row("volsr", "VolSR S 4x", 45.0, 30.0, 4)  # 30 dB in 45 ms: the budget, the native PSNR
    on_margin = row("volsr", "VolSR S 2x", 20.0, 24.5, 2)  # the curve at 20 ms is 24 dB: 0.5 above
    on_curve = row("volsr", "VolSR S 8x", 20.0, 24.49, 8)  # 0.49 above
    t = check_targets(base + [edge, on_margin, on_curve])["v"]
    assert [p["met"] for p in t["fast_4x"]["points"]] == [True] and t["fast_4x"]["met"] is True
    assert [p["met"] for p in t["above_bilinear"]["points"]] == [True, True, False]  # edge: 30 dB, curve 27 dB
    assert t["above_bilinear"]["met"] is False
    assert t["above_bilinear"]["points"][1]["margin_db"] == pytest.approx(0.5)
    just_slow = {**edge, "scene": "w", "ms_total": 45.001}
    just_weak = {**edge, "scene": "w", "label": "VolSR M 4x", "psnr": 29.999}
    other = [{**r, "scene": "w"} for r in base] + [just_slow, just_weak]
    both = check_targets(base + [edge] + other)
    assert both["v"]["fast_4x"]["met"] is True and both["w"]["fast_4x"]["met"] is False
    assert [p["met"] for p in both["w"]["fast_4x"]["points"]] == [False, False]


def test_each_timing_pass_gives_a_margin_against_its_own_curve():
    """With the times of several passes over the orbit, a VolSR point's margin in each pass is its time in that pass
    against the curve through the baseline's times in that pass (the same PSNRs): here the point clears the margin
    on the medians and in pass 2, where the curve's 1/4-size point ran slow, but not in pass 3, where it did."""
    def timed(r, passes):
        return {**r, "ms_total_passes": passes}

    base = [timed(row("native", "native 1 spp", 90.0, 30.0), [90.0, 90.0, 90.0]),
            timed(row("bilinear", "1/2", 30.0, 26.0, 2), [30.0, 30.0, 30.0]),
            timed(row("bilinear", "1/4", 10.0, 22.0, 4), [10.0, 12.0, 10.0])]
    point = timed(row("volsr", "VolSR XS 2x", 20.0, 24.6, 2), [20.0, 20.0, 25.0])
    p = check_targets(base + [point])["v"]["above_bilinear"]["points"][0]
    assert p["met"] and p["margin_db"] == pytest.approx(0.6)
    # pass 2: the curve at 20 ms runs from (12, 22) to (30, 26): 22 + 8 * 4 / 18; pass 3: the point at 25 ms, 25 dB
    assert p["margin_db_passes"] == pytest.approx([0.6, 24.6 - (22.0 + 8.0 * 4.0 / 18.0), -0.4], abs=1e-4)
    assert "(+0.60 dB; each pass +0.60 / +0.82 / -0.40): yes" in target_lines(check_targets(base + [point])["v"])[-1]
    one_pass = {**point, "ms_total_passes": [20.0]}  # a run of one pass, or rows of an older version: no margins
    uneven = {**point, "ms_total_passes": [20.0, 20.0]}
    not_finite = {**point, "ms_total_passes": [20.0, None, 25.0]}  # bench.json writes a non-finite time as null
    for other in (one_pass, uneven, not_finite, row("volsr", "VolSR XS 2x", 20.0, 24.6, 2)):
        p = check_targets(base + [other])["v"]["above_bilinear"]["points"][0]
        assert "margin_db_passes" not in p and "each pass" not in target_lines(check_targets(base + [other])["v"])[-1]


def test_scene_specs(tmp_path):
    assert parse_scene_spec(None) == (None, None, None)
    assert parse_scene_spec("phantom") == (None, None, None)
    assert parse_scene_spec("phantom:CT-Bone") == (None, "CT-Bone", None)
    assert parse_scene_spec("a/CT_AVM.nii.gz:CT-AAA:0,446") == ("a/CT_AVM.nii.gz", "CT-AAA", (0.0, 446.0))
    assert parse_scene_spec("bonsai.nii.gz:CT-Bone") == ("bonsai.nii.gz", "CT-Bone", None)
    assert parse_scene_spec("bonsai.nii.gz:CT-Bone:auto") == ("bonsai.nii.gz", "CT-Bone", "auto")
    assert parse_scene_spec("LIDC2.mha:0,255") == ("LIDC2.mha", None, (0.0, 255.0))
    assert parse_scene_spec("LIDC2.mha::-5.5,2e3") == ("LIDC2.mha", None, (-5.5, 2000.0))
    odd = tmp_path / "scan:1.nrrd"
    odd.write_bytes(b"")
    assert parse_scene_spec(str(odd)) == (str(odd), None, None)
    assert parse_scene_spec(f"{odd}:MR-Default") == (str(odd), "MR-Default", None)


def test_resize_to_any_size_matches_bilinear_at_integer_ratios():
    rng = np.random.default_rng(0)
    lr = rng.random((6, 5, 3), dtype=np.float32)
    assert np.allclose(resize_bilinear(lr, 20, 24), upscale_bilinear(lr, 4), atol=1e-6)
    odd = resize_bilinear(lr, 16, 17)  # 5 -> 16 and 6 -> 17: not integer ratios
    assert odd.shape == (17, 16, 3) and odd.dtype == np.float32

    def taps(n_in, n_out, i):  # output pixel i samples input coordinate (i + 0.5) n_in / n_out - 0.5
        s = (i + 0.5) * n_in / n_out - 0.5
        f = math.floor(s)
        return min(max(f, 0), n_in - 1), min(max(f + 1, 0), n_in - 1), s - f

    for y, x in [(0, 0), (16, 15), (7, 3), (11, 12)]:
        a, b, fy = taps(6, 17, y)
        c, d, fx = taps(5, 16, x)
        expected = ((1 - fy) * ((1 - fx) * lr[a, c] + fx * lr[a, d]) + fy * ((1 - fx) * lr[b, c] + fx * lr[b, d]))
        assert np.allclose(odd[y, x], expected, atol=1e-6)
    assert np.allclose(resize_bilinear(np.full((6, 5, 3), 0.25, np.float32), 16, 17), 0.25)
    assert lr.min() <= odd.min() and odd.max() <= lr.max()
    assert resize_bilinear(lr[..., 0], 10, 12).shape == (12, 10)


def test_timing_passes_run_fresh_methods_over_the_same_orbit_and_leave_the_scores_alone():
    from volsr_core.apps.bench.run import bench_one, build_methods
    from volsr_core.apps.bench.scenes import load_bench_volume
    from volsr_core.render.raycaster import RayCaster
    from volsr_core.scene.camera_paths import orbit_around

    scene = load_bench_volume(None, None, "auto")
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    size = (32, 32)
    cameras = orbit_around(caster.visible_bounds(), 4, 2.0)

    def methods():
        return build_methods(scene, caster, size, spp=(1,), factors=(2,), scales=(2,), threads=1)

    calls = []

    class Counted:  # a method that notes each frame it renders
        def __init__(self, method):
            self.method = method

        def __getattr__(self, name):
            return getattr(self.method, name)

        def __call__(self, camera):
            calls.append(id(self))
            return self.method(camera)

    one = bench_one(scene, caster, size, methods(), cameras, reference_spp=4, warmup=1)
    extra = [[Counted(m) for m in methods()] for _ in range(2)]
    three = bench_one(scene, caster, size, methods(), cameras, reference_spp=4, warmup=1, timing_passes=iter(extra))
    assert len(calls) == 2 * len(cameras) * len(extra[0]), "every fresh method renders every frame of its pass"
    assert {id(m) for m in extra[0] + extra[1]} == set(calls)
    for a, b in zip(one, three):  # the scored pass is the same work: the same quality, frame for frame
        assert a["label"] == b["label"] and a["psnr_frames"] == pytest.approx(b["psnr_frames"], abs=1e-6)
        assert len(a["ms_total_frames"]) == 3 and len(b["ms_total_frames"]) == 9 and len(b["ms_total_passes"]) == 3
    with pytest.raises(ValueError, match="the scored pass.s methods, in its order"):
        bench_one(scene, caster, size, methods(), cameras, reference_spp=4, warmup=1,
                  timing_passes=[methods()[::-1]])


def test_the_ground_truth_is_rendered_for_the_scored_frames_alone_and_the_progress_bar_counts_every_render():
    """The warm-up frames are not scored, so their ground truth (``reference_spp`` renders each, the costliest part of a
    1024² run after the methods) is not made; the progress bar's steps are the truths made and the methods' frames."""
    from volsr_core.apps.bench.run import bench_one, build_methods
    from volsr_core.apps.bench.scenes import load_bench_volume
    from volsr_core.render.raycaster import RayCaster
    from volsr_core.scene.camera_paths import orbit_around

    scene = load_bench_volume(None, None, "auto")
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    size, warmup, spp = (24, 16), 2, 3
    cameras = orbit_around(caster.visible_bounds(), 5, 2.0)
    methods = build_methods(scene, caster, size, spp=(1,), factors=(2,), scales=(), threads=1)
    sizes = []
    render_color = caster.render_color

    def noted(camera, width, height, **kwargs):  # the ray caster's own render, its image sizes noted
        sizes.append((width, height))
        return render_color(camera, width, height, **kwargs)

    caster.render_color = noted

    class Steps:  # what bench_one asks of a tqdm bar
        count = 0

        def update(self, n: int = 1) -> None:
            self.count += n

        def set_postfix_str(self, text: str) -> None:
            pass

    steps = Steps()
    rows = bench_one(scene, caster, size, methods, cameras, reference_spp=spp, warmup=warmup, progress=steps)
    truths = len(cameras) - warmup
    assert sizes.count(size) == truths * spp + len(cameras), "the truth's renders and native 1 spp's, nothing more"
    assert steps.count == truths + len(cameras) * len(methods)
    assert all(len(row["psnr_frames"]) == truths for row in rows)


def test_the_scored_pass_scores_each_frame_as_it_was_rendered_from_methods_that_reuse_their_buffer():
    """The scored pass keeps its images in a store per method, made once (a copy a frame grew the heap between the
    methods' frames and slowed every method's frames in that pass: docs/performance.md); each frame is scored as it
    was rendered, also from a method that writes every frame into the same buffer, and the stores of two methods
    stay apart."""
    from volsr_core.apps.bench.run import bench_one
    from volsr_core.apps.bench.scenes import load_bench_volume
    from volsr_core.render.raycaster import RayCaster
    from volsr_core.runtime.methods import Method, MethodFrame
    from volsr_core.scene.camera_paths import orbit_around
    from volsr_core.sr.metrics import psnr_ssim
    from volsr_core.temporal.ground_truth import supersampled_truth

    scene = load_bench_volume(None, None, "auto")
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    size, warmup = (24, 16), 1
    cameras = orbit_around(caster.visible_bounds(), 5, 2.0)

    class Grey(Method):  # one grey a frame, written into the same buffer every frame
        kind = "native"

        def __init__(self, start: float):
            super().__init__(size)
            self.start, self.frame = start, 0
            self.buffer = np.empty((size[1], size[0], 3), np.float32)

        @property
        def label(self) -> str:
            return f"grey from {self.start}"

        def __call__(self, camera) -> MethodFrame:
            self.buffer[...] = self.start + 0.1 * self.frame
            self.frame += 1
            return MethodFrame(self.buffer, 1.0)

    rows = bench_one(scene, caster, size, [Grey(0.1), Grey(0.3)], cameras, reference_spp=2, warmup=warmup)
    truth = [supersampled_truth(caster, camera, t, *size, 2) for t, camera in enumerate(cameras)]
    for row, start in zip(rows, (0.1, 0.3)):
        expected = [psnr_ssim(np.full((size[1], size[0], 3), start + 0.1 * t, np.float32), truth[t],
                              channel_axis=-1)[0] for t in range(warmup, len(cameras))]
        assert row["psnr_frames"] == pytest.approx(expected, abs=1e-4)  # as the rows round them


def test_bad_settings_give_one_line_errors(tmp_path):
    from volsr_core.cli import main

    assert main(["bench", "--size", "60", "--scales", "8", "--out", str(tmp_path / "b")]) == 2
    assert main(["bench", "--size", "64", "--spp", "16", "--out", str(tmp_path / "b")]) == 2
    assert main(["bench", "--size", "64", "--frames", "2", "--warmup", "2", "--out", str(tmp_path / "b")]) == 2
    with pytest.raises(SystemExit) as exit_:  # argparse's own one-line usage error
        main(["bench", "--size", "64", "--timing-passes", "0", "--out", str(tmp_path / "b")])
    assert exit_.value.code == 2
    from volsr_core.apps.bench.run import run_benchmark
    from volsr_core.errors import InputError

    with pytest.raises(InputError, match="at least 1 timing pass"):
        run_benchmark(size=(64, 64), timing_passes=0, progress=False)


def test_vtk_row_is_vtks_own_mapper_in_the_same_run(tmp_path):
    pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2")
    pytest.importorskip("skimage")
    from volsr_core.cli import main

    out = tmp_path / "b"
    assert main(["bench", "--size", "32", "--frames", "2", "--warmup", "1", "--reference-spp", "2", "--spp", "1",
                 "--factors", "2", "--scales", "2", "--variants", "", "--vtk", "fixed_point", "--out", str(out)]) == 0
    rows = by_label(json.loads((out / "bench.json").read_text()))
    vtk, native = rows["VTK CPU mapper"], rows["native 1 spp"]
    assert vtk["method"] == "vtk" and vtk["ms_total"] > 0 and vtk["ms_network"] == 0
    assert vtk["psnr"] > 15, "VTK draws the same volume, framing and look (not identical: another renderer)"
    assert abs(vtk["psnr"] - native["psnr"]) < 25
    assert "| VTK CPU mapper |" in (out / "bench.md").read_text()


def test_the_stretched_rows_are_the_models_whose_scale_times_the_stretch_is_benchmarked():
    from volsr_core.apps.bench.run import ModelSpec, model_scales, volsr_rows

    assert model_scales([2, 4, 8], [2]) == [2, 4, 8] and model_scales([4], [2]) == [2, 4]
    assert model_scales([4, 8], [2, 4]) == [2, 4, 8] and model_scales([2], [2]) == [2]  # no 1x model
    xs2, s4, s8 = ModelSpec("xs2.onnx", "XS", 2), ModelSpec("s4.onnx", "S", 4), ModelSpec("s8.onnx", "S", 8)
    assert volsr_rows([xs2, s4, s8], [2, 4, 8], [2]) == [(xs2, 1), (xs2, 2), (s4, 1), (s4, 2), (s8, 1)]
    assert volsr_rows([xs2, s4], [4], [2]) == [(xs2, 2), (s4, 1)]
    assert volsr_rows([xs2, s4], [2, 4, 8], [1]) == [(xs2, 1), (s4, 1)], "stretch 1: no stretched rows"


def test_a_model_is_the_variant_of_its_fold_whatever_its_widths():
    from volsr_core.apps.bench.run import infer_variant
    from volsr_core.sr.network_config import NetworkConfig, variant_config

    def sized(variant, scale, **sizes):
        base = variant_config(variant, scale, 0, taau_base=True)
        return NetworkConfig(**{**base.to_dict(), **sizes})

    assert infer_variant(sized("S", 4, widths=(16, 24, 32), reweight_width=16)) == "S"
    assert infer_variant(sized("M", 4, widths=(16, 24))) == "M"
    assert [infer_variant(variant_config(v, 2, 0)) for v in ("XS", "S", "M", "L")] == ["XS", "S", "M", "L"]
    assert infer_variant(sized("L", 2, widths=(8, 12))) == "M"  # M and L both fold 1 at 2x: the smaller


def test_two_models_of_one_variant_and_scale_go_by_their_file_names(tmp_path):
    import shutil

    pytest.importorskip("onnxruntime")
    from volsr_core.apps.bench.run import find_models
    from volsr_core.runtime.models import model_file

    for name in ("before", "after"):
        shutil.copy(model_file("S", 4, "onnx"), tmp_path / f"{name}.onnx")
    shutil.copy(model_file("XS", 2, "onnx"), tmp_path / "xs.onnx")
    found = {(m.variant, m.scale) for m in find_models(tmp_path, variants=["XS"])}
    assert found == {("XS", 2), ("after", 4), ("before", 4)}
