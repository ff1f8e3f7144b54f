"""`volsr upscale` end to end on real files: PNG frames, MP4s, side-by-side panels, bad inputs among
good ones, interrupted writes, and the --variant auto rule."""
from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("onnxruntime")
imageio = pytest.importorskip("imageio.v2")
pytest.importorskip("imageio_ffmpeg")

from volsr_core.cli import build_parser, main  # noqa: E402
from volsr_core.hashing import file_sha256  # noqa: E402
from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.apps import upscale as batch  # noqa: E402
from volsr_core.runtime import models  # noqa: E402


@pytest.fixture(scope="module")
def small_volume(tmp_path_factory):
    """The phantom at 32^3 as a MetaImage file: a real volume file that loads fast."""
    import SimpleITK as sitk

    record = make_phantom(shape=(32, 32, 32))
    image = sitk.GetImageFromArray(record.array)
    image.SetSpacing(record.spacing)
    image.SetOrigin(record.origin)
    image.SetDirection(np.asarray(record.direction, dtype=float).ravel().tolist())
    path = tmp_path_factory.mktemp("volumes") / "small.mha"
    sitk.WriteImage(image, str(path))
    return path


def one_layer_u_net(path):
    """A small U-Net on the one-layer TAAU (no ``taau_slabs``), exported to ``path``: a model that takes no depth
    slabs."""
    pytest.importorskip("torch")
    from volsr_core.runtime.export import export_onnx
    from volsr_core.sr.network import SuperResolutionNet
    from volsr_core.sr.network_config import NetworkConfig

    config = NetworkConfig(scale=4, previous_frames=0, fold=4, widths=(8, 12), taau_base=True)
    return export_onnx(SuperResolutionNet(config), path, example_size=(8, 12))


def leftovers(folder):
    """Temporary or partial files anywhere under ``folder``."""
    return [p for p in folder.rglob("*") if p.name.startswith(".") or ".part" in p.name]


def read_video(path):
    reader = imageio.get_reader(path)
    try:
        return [np.asarray(f) for f in reader]
    finally:
        reader.close()


def test_phantom_orbit_to_png_frames_and_mp4_with_psnr_summary(tmp_path, model, capsys):
    video = tmp_path / "movie.mp4"
    code = main(["upscale", "--orbit", "3", "--size", "64", "--model", str(model), "--out", str(tmp_path / "out"),
                 "--video", str(video), "--reference-spp", "2"])
    assert code == 0
    pngs = sorted((tmp_path / "out" / "phantom").glob("*.png"))
    assert [p.name for p in pngs] == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    images = [np.asarray(Image.open(p)) for p in pngs]
    assert all(im.shape == (64, 64, 3) for im in images) and images[0].max() > 30
    frames = read_video(video)
    assert len(frames) == 3 and frames[0].shape == (64, 64, 3)
    assert np.abs(frames[0].astype(float) - images[0]).mean() < 12  # the MP4 holds the same pictures
    out = capsys.readouterr().out
    assert "upscaled 1 of 1 input(s) 4x with volsr-S-4x.onnx" in out
    line = next(line for line in out.splitlines() if line.strip().startswith("phantom:"))
    assert "3 frames of 64x64 from 16x16" in line and "network" in line
    assert "mean PSNR vs 2-spp native" in line and "VolSR" in line and "bilinear" in line
    summary = (tmp_path / "out" / "summary.md").read_text()
    rows = [row.split("|")[1:-1] for row in summary.splitlines() if row.startswith("| phantom")]
    assert [r[3].strip() for r in rows] == ["VolSR", "bilinear"], "every method measured, with its time and PSNR"
    assert all(float(r[4]) > 0 and 5 < float(r[6]) < 100 for r in rows)
    assert not leftovers(tmp_path)


def test_side_by_side_frames_are_three_panels_wide(tmp_path, model):
    code = main(["upscale", "--orbit", "2", "--size", "64x48", "--model", str(model), "--side-by-side",
                 "--out", str(tmp_path), "--video", str(tmp_path / "sbs.mp4")])
    assert code == 0
    png = np.asarray(Image.open(tmp_path / "phantom" / "frame_0001.png"))
    assert png.shape == (48, 192, 3)
    native, bilinear, volsr = png[:, :64], png[:, 64:128], png[:, 128:]
    assert not np.array_equal(native, bilinear) and not np.array_equal(bilinear, volsr)
    for panel in (native, bilinear, volsr):  # white label text on a black box in the top-left corner
        corner = panel[:16, :40]
        assert (corner.min(axis=-1) > 120).any() and np.all(corner == 0, axis=-1).any()
    frames = read_video(tmp_path / "sbs.mp4")
    assert len(frames) == 2 and frames[0].shape == (48, 192, 3)
    summary = (tmp_path / "summary.md").read_text()
    native_row = next(row for row in summary.splitlines() if "| native 1 spp |" in row)
    assert native_row.split("|")[6].strip() == "1.00", "times are shown against the native 1-spp render's"


def test_dicom_folder(tmp_path, model, headsq_dicom, capsys):
    code = main(["upscale", str(headsq_dicom), "--orbit", "2", "--size", "48", "--model", str(model),
                 "--out", str(tmp_path), "--video", str(tmp_path / "videos")])
    assert code == 0
    pngs = sorted((tmp_path / "headsq_dicom").glob("frame_*.png"))
    assert len(pngs) == 2 and np.asarray(Image.open(pngs[0])).shape == (48, 48, 3)
    frames = read_video(tmp_path / "videos" / "headsq_dicom.mp4")
    assert len(frames) == 2 and frames[0].shape == (48, 48, 3)
    assert "headsq_dicom: 2 frames of 48x48 from 12x12" in capsys.readouterr().out


def test_bad_inputs_are_reported_while_the_good_ones_finish(tmp_path, model, small_volume, capsys):
    bogus = tmp_path / "bogus.nrrd"
    bogus.write_text("this is not a volume\n")
    listing = tmp_path / "list.txt"
    listing.write_text(f"# volumes\n{small_volume}\nmissing.nii.gz\n\nbogus.nrrd\n")
    code = main(["upscale", str(listing), str(small_volume), "--orbit", "2", "--size", "32", "--model", str(model),
                 "--out", str(tmp_path / "out"), "--video", str(tmp_path / "out" / "all.mp4")])
    assert code == 1
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("volsr: error:")]
    assert len(errors) == 2
    assert errors[0] == f"volsr: error: {tmp_path / 'missing.nii.gz'}: no such file or folder"
    assert errors[1].startswith(f"volsr: error: {bogus}: content does not look like a NRRD file")
    assert "upscaled 2 of 4 input(s) 4x with volsr-S-4x.onnx, 2 failed" in captured.out
    assert "missing: FAILED" in captured.out and "bogus: FAILED" in captured.out
    for name in ("small", "small_2"):  # the same file twice: two names
        assert len(list((tmp_path / "out" / name).glob("frame_*.png"))) == 2
        assert len(read_video(tmp_path / "out" / f"{name}.mp4")) == 2
    assert sorted(p.name for p in (tmp_path / "out").glob("*.mp4")) == ["small.mp4", "small_2.mp4"]
    assert not leftovers(tmp_path)


def test_bad_arguments_exit_2_with_one_line(tmp_path, model, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["upscale", "--model", str(tmp_path / "none.onnx"), "--out", str(tmp_path)]) == 2
    assert "none.onnx: cannot read the model" in capsys.readouterr().err
    assert main(["upscale", "--model", str(model), "--scale", "2", "--out", str(tmp_path)]) == 2
    assert "upscales 4x, not 2x" in capsys.readouterr().err
    assert main(["upscale", "--model", str(model), "--out", str(blocker)]) == 2
    assert main(["upscale", "--model", str(model), "--out", str(tmp_path), "--video", str(blocker / "x.mp4")]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    one_layer = one_layer_u_net(tmp_path / "one_layer.onnx")  # every shipped U-Net refines the layered TAAU
    assert main(["upscale", "--model", str(one_layer), "--slabs", "2", "--out", str(tmp_path)]) == 2
    assert "one_layer.onnx: takes no depth slabs (--slabs 2)" in capsys.readouterr().err
    assert main(["upscale", "--slabs", "1", "--budget-ms", "50", "--out", str(tmp_path)]) == 2
    assert "--slabs: --budget-ms runs each model with its own depth slabs" in capsys.readouterr().err
    assert main(["upscale", "--scale", "4", "--stretch", "3", "--out", str(tmp_path)]) == 2
    assert "--stretch: 3 does not divide --scale 4" in capsys.readouterr().err
    assert main(["upscale", "--scale", "4", "--stretch", "4", "--out", str(tmp_path)]) == 2
    assert "--stretch: 4 leaves the model no upscaling at --scale 4" in capsys.readouterr().err
    assert main(["upscale", "--stretch", "2", "--budget-ms", "50", "--out", str(tmp_path)]) == 2
    assert "--stretch: --budget-ms chooses its own levels" in capsys.readouterr().err
    assert main(["upscale", "--model", str(model), "--scale", "4", "--stretch", "2", "--out", str(tmp_path)]) == 2
    assert "upscales 4x, not 2x (--scale 4 / --stretch 2)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:
        main(["upscale", "--stretch", "0", "--out", str(tmp_path)])
    assert stopped.value.code == 2 and "must be auto or an integer in [1, 8], got '0'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:
        main(["upscale", "--slabs", "9", "--out", str(tmp_path)])
    assert stopped.value.code == 2 and "must be auto or an integer in [0, 8], got '9'" in capsys.readouterr().err


def test_without_scale_variant_or_model_it_runs_volsr_xs_2x(tmp_path, capsys):
    """The defaults are the model that pays off on a CPU (docs/performance.md); --scale alone takes the smallest
    variant shipped at that scale."""
    assert main(["upscale", "--orbit", "2", "--size", "32", "--out", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "upscaled 1 of 1 input(s) 2x with volsr-XS-2x.onnx" in out and "from 16x16" in out
    assert main(["upscale", "--orbit", "1", "--size", "32", "--scale", "8", "--out", str(tmp_path / "b")]) == 0
    assert "8x (4x + bicubic 2x) with volsr-XS-4x.onnx" in capsys.readouterr().out  # the 8x U-Net only when named
    assert main(["upscale", "--orbit", "1", "--size", "32", "--scale", "8", "--variant", "S",
                 "--out", str(tmp_path / "b")]) == 0
    assert "8x with volsr-S-8x.int8.onnx" in capsys.readouterr().out  # a U-Net on the CPU: its 8-bit file
    assert main(["upscale", "--orbit", "2", "--size", "32", "--scale", "4", "--out", str(tmp_path / "c")]) == 0
    assert "4x with volsr-XS-4x.onnx" in (out := capsys.readouterr().out) and "from 8x8 in 2 depth slabs" in out
    assert main(["upscale", "--orbit", "2", "--size", "32", "--scale", "4", "--slabs", "0",
                 "--out", str(tmp_path / "d")]) == 0
    assert "from 8x8;" in capsys.readouterr().out
    assert main(["upscale", "--orbit", "2", "--size", "32", "--scale", "4", "--stretch", "2",
                 "--out", str(tmp_path / "e")]) == 0  # the 2x model to 16x16, stretched
    out = capsys.readouterr().out
    assert "4x (2x + bicubic 2x) with volsr-XS-2x.onnx" in out and "from 8x8, the model's image stretched 2x;" in out
    assert "# volsr upscale: 4x (2x + bicubic 2x) with volsr-XS-2x.onnx" in (tmp_path / "e/summary.md").read_text()
    # --stretch auto, the default: where a voxel spans two output pixels or more (the phantom filling 512²), XS 2x
    assert main(["upscale", "--orbit", "1", "--size", "512", "--scale", "4", "--out", str(tmp_path / "f")]) == 0
    out = capsys.readouterr().out
    assert "4x with volsr-XS-4x.onnx or stretched by the view and its turn (--stretch auto)" in out
    assert "from 128x128, the model's image stretched 2x;" in out
    # ... and while the view turns fast for its sampling (15° a frame, 0.36 pixels per voxel at 64²), the first frame
    # XS 4x's and the rest the stretched model's
    assert main(["upscale", "--orbit", "4", "--degrees", "15", "--size", "64", "--scale", "4",
                 "--out", str(tmp_path / "g")]) == 0
    out = capsys.readouterr().out
    models = "volsr-XS-4x.onnx in 2 depth slabs 1, volsr-XS-2x.onnx stretched 2x 3"
    assert "from 16x16; VolSR" in out and f"frames per model (--stretch auto): {models}" in out
    assert f"- phantom: {models}" in (tmp_path / "g/summary.md").read_text()


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_an_interrupted_run_leaves_complete_files_only(tmp_path, model, small_volume, stop):
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Camera, Volume, get_preset
    from volsr_core.scene.camera_paths import orbit

    volume = Volume.load(small_volume)
    pipeline = Pipeline(volume, get_preset("CT-Bone").placed_on(*volume.percentiles()), model, size=(32, 32))
    cameras = orbit(Camera.framing(volume.bounds), 4)

    def interrupt(i):
        if i == 1:
            raise stop("stopped after the second frame")

    with pytest.raises(stop):
        batch.upscale_cameras(pipeline, cameras, tmp_path / "frames", video=tmp_path / "movie.mp4", progress=False,
                              side_by_side_panels=True, on_frame=interrupt)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["frame_0000.png", "frame_0001.png", "frames"]
    assert all(np.asarray(Image.open(p)).shape == (32, 96, 3) for p in (tmp_path / "frames").glob("*.png"))


def test_auto_variant_rule(capsys):
    assert batch.choose_variant({"L": 90, "M": 40, "S": 10}, budget_ms=50) == "M"
    assert batch.choose_variant({"L": 49, "M": 40, "S": 10}, budget_ms=50) == "L"
    assert batch.choose_variant({"L": 90, "M": 60, "S": 55}, budget_ms=50) == "S"  # none fits: the fastest
    assert batch.choose_variant({("S", 1): 60, ("M", 2): 70, ("XS", 2): 65}, budget_ms=50) == ("S", 1)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["upscale", "--help"])
    assert "half the time of one LR render" in " ".join(capsys.readouterr().out.split())


def test_variant_auto_where_no_model_ships_takes_a_stretched_one(tmp_path, monkeypatch, small_volume, capsys):
    """At 16x, where no model ships, ``--variant auto`` times the shipped 8x, 4x and 2x models (stretched 2x, 4x and
    8x), the whole scale's first and each scale's larger variants first, and runs the first whose network fits half
    the LR render, else the fastest: the times measured here decide what it must have taken."""
    measured: dict[str, float] = {}
    network_ms, render_ms = batch.network_ms, batch.render_ms
    monkeypatch.setattr(batch, "network_ms", lambda engine, *a: measured.setdefault(engine.path.name,
                                                                                   network_ms(engine, *a)))
    monkeypatch.setattr(batch, "render_ms", lambda *a: measured.setdefault("lr render", render_ms(*a)))
    code = main(["upscale", str(small_volume), "--variant", "auto", "--scale", "16", "--orbit", "1", "--size", "64",
                 "--out", str(tmp_path / "out")])
    assert code == 0
    out = capsys.readouterr().out
    budget = models.PAYING_NETWORK_SHARE * measured.pop("lr render")
    shipped = {(e["variant"], e["scale"]): models.model_file_to_run(e["variant"], e["scale"]).name
               for e in models.shipped_models()}
    order = [shipped[v, m] for m in (8, 4, 2) for v in ("L", "M", "S", "XS") if (v, m) in shipped]
    timed = list(measured)
    assert timed == order[:len(timed)], "timed in the rule's order"
    fits = [name for name in timed if measured[name] <= budget]
    assert fits in ([], timed[-1:]), "timing stops at the first that fits"
    chosen = fits[0] if fits else min(timed, key=measured.get)
    model_scale = int(chosen.split("-")[-1].split("x")[0])
    assert f"with {chosen}" in out and f"stretched {16 // model_scale}x" in out
    assert np.asarray(Image.open(tmp_path / "out" / "small" / "frame_0000.png")).shape == (64, 64, 3)


@pytest.fixture(scope="module")
def registry_s_m(tmp_path_factory, model):
    """A models folder shipping S and M at 4x (copies of the shipped ones), as models.json lists them."""
    import shutil

    folder = tmp_path_factory.mktemp("registry")
    shutil.copy(model, folder / "s4.onnx")
    shutil.copy(models.model_file("M", 4), folder / "m4.onnx")
    entries = [{"name": f"volsr-{v.lower()}4", "variant": v, "scale": 4, "files": {"onnx": f"{v.lower()}4.onnx"},
                "sha256": {"onnx": file_sha256(folder / f"{v.lower()}4.onnx")}} for v in ("S", "M")]
    (folder / "models.json").write_text(json.dumps({"models": entries}))
    return folder


def run_auto(tmp_path, small_volume, capsys) -> tuple[str, str]:
    """``volsr upscale --variant auto`` on the small volume: (the variant chosen, all it printed)."""
    code = main(["upscale", str(small_volume), "--variant", "auto", "--scale", "4", "--orbit", "1", "--size", "32",
                 "--out", str(tmp_path / "out")])
    assert code == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if line.startswith("variant auto:"))
    assert "of the 8x8 LR render" in line
    assert (tmp_path / "out" / "small" / "frame_0000.png").is_file()
    return line.rsplit("-> ", 1)[1], out


def test_variant_auto_picks_from_the_shipped_registry(tmp_path, monkeypatch, registry_s_m, small_volume, capsys):
    """The times measured on this machine, recorded as they are taken, decide the variant the rule must pick."""
    monkeypatch.setattr(models, "models_dir", lambda: registry_s_m)
    measured: dict[str, float] = {}
    network_ms, render_ms = batch.network_ms, batch.render_ms
    monkeypatch.setattr(batch, "network_ms", lambda engine, *a: measured.setdefault(engine.path.name,
                                                                                   network_ms(engine, *a)))
    monkeypatch.setattr(batch, "render_ms", lambda *a: measured.setdefault("lr render", render_ms(*a)))
    chosen, out = run_auto(tmp_path, small_volume, capsys)
    m_fits = measured["m4.onnx"] <= models.PAYING_NETWORK_SHARE * measured["lr render"]
    assert chosen == ("M 4x" if m_fits else "S 4x")
    assert ("s4.onnx" in measured) is not m_fits, "S is timed only when M does not fit"
    assert f"with {chosen[0].lower()}4.onnx" in out


@pytest.mark.parametrize("budget, expected", [(50.0, "M"), (40.0, "M"), (39.0, "S")])
def test_variant_auto_takes_the_largest_that_fits_the_budget(tmp_path, monkeypatch, registry_s_m, small_volume,
                                                              capsys, budget, expected):
    """M takes 40 ms and S 10 ms per frame: M fits a budget (half the LR render) of 40 ms or more, S the rest."""
    monkeypatch.setattr(models, "models_dir", lambda: registry_s_m)
    monkeypatch.setattr(batch, "network_ms", lambda engine, *a: {"m4.onnx": 40.0, "s4.onnx": 10.0}[engine.path.name])
    monkeypatch.setattr(batch, "render_ms", lambda caster, camera, size: 2 * budget if size == (8, 8) else 0.0)
    chosen, out = run_auto(tmp_path, small_volume, capsys)
    assert chosen == f"{expected} 4x" and f"with {expected.lower()}4.onnx" in out
    times = "M 4x 40 ms" if expected == "M" else "M 4x 40 ms, S 4x 10 ms"
    assert (f"network per 32x32 frame {times}; budget {budget:.0f} ms (0.5 of the 8x8 LR render, {2 * budget:.0f} ms)"
            f" -> {expected} 4x") in out
