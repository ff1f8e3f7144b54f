"""The shipped models: registered, SHA-256 checked, small, the ONNX and PyTorch files agree, and each beats
bilinear upscaling on a phantom orbit, above a PSNR floor."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.render import RayCaster  # noqa: E402
from volsr_core.runtime import models  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine  # noqa: E402
from volsr_core.runtime.export import example_inputs  # noqa: E402
from volsr_core.runtime.methods import ReducedSize  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.scene import Volume, get_preset  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402
from volsr_core.sr.checkpoint import load_model  # noqa: E402
from volsr_core.sr.metrics import psnr_ssim  # noqa: E402
from volsr_core.temporal import render_supersampled  # noqa: E402

SHIPPED = models.shipped_models()


def test_the_4x_model_of_variant_s_is_shipped():
    assert any(m["variant"] == "S" and m["scale"] == 4 for m in SHIPPED), "resources/models/models.json lists it"


def test_the_default_is_xs_2x_and_a_scale_alone_takes_the_smallest_model_shipped_there():
    """What hosts and ``volsr upscale`` run unless told: VolSR XS 2x, the model above the native + bilinear
    curve at equal time on a CPU (docs/performance.md)."""
    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    tf = get_preset("CT-Phantom")
    by_default = Pipeline(volume, tf, size=(32, 32))
    assert (by_default.scale, by_default.engine.path.name) == (2, "volsr-XS-2x.onnx")
    assert [models.default_variant(s) for s in (2, 4, 8)] == ["XS", "XS", "S"]
    assert Pipeline(volume, tf, scale=8, size=(32, 32)).engine.path.name == "volsr-S-8x.int8.onnx"
    assert Pipeline(volume, tf, scale=4, variant="S", size=(32, 32)).engine.path.name == "volsr-S-4x.int8.onnx"


def test_the_cpu_runs_the_8_bit_file_where_one_ships_and_a_gpu_the_float32_one():
    """Every shipped U-Net ships an 8-bit ONNX file (training/quantize_model.py): the file hosts, ``volsr upscale`` and
    ``volsr bench`` run on the CPU; a GPU runs the float32 file, and so does XS everywhere (its own kernel reads the
    weights in the float32 file's metadata)."""
    for entry in SHIPPED:
        name = f"{entry['name']}.int8.onnx" if entry["variant"] != "XS" else f"{entry['name']}.onnx"
        assert models.model_file_to_run(entry["variant"], entry["scale"]).name == name
        assert models.model_file_to_run(entry["variant"], entry["scale"], device="cuda").name == entry["files"]["onnx"]
    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), scale=2, variant="S", size=(32, 32))
    assert pipeline.engine.path.name == "volsr-S-2x.int8.onnx"
    assert pipeline.engine.config == OnnxEngine(models.model_file("S", 2)).config


@pytest.mark.parametrize("entry", SHIPPED, ids=[m["name"] for m in SHIPPED])
def test_a_shipped_model_is_small_checked_and_its_two_files_agree(entry):
    onnx_path = models.model_file(entry["variant"], entry["scale"], "onnx")
    pt_path = models.model_file(entry["variant"], entry["scale"], "pt")
    assert onnx_path.stat().st_size <= 10 * 2**20 and pt_path.stat().st_size <= 10 * 2**20
    raw = torch.load(pt_path, map_location="cpu", weights_only=True)
    assert raw["format"] == "volsr-model"
    net = load_model(pt_path, expected_sha256=entry["sha256"]["pt"])
    engine = OnnxEngine(onnx_path, providers=["CPUExecutionProvider"])
    assert engine.config == net.config and net.config.scale == entry["scale"]
    inputs = example_inputs(net.config, 11, 9)
    with torch.no_grad():
        expected = net(*inputs).numpy()
    assert np.abs(engine(*(x.numpy() for x in inputs)) - expected).max() <= 1e-4
    assert (models.models_dir() / entry["files"]["card"]).is_file()
    if models.INT8_KIND in entry["files"]:  # SHA-256 checked, small, the same network
        int8_path = models.model_file(entry["variant"], entry["scale"], models.INT8_KIND)
        assert int8_path.stat().st_size <= 10 * 2**20
        assert OnnxEngine(int8_path, providers=["CPUExecutionProvider"]).config == net.config


def test_a_damaged_shipped_file_is_refused_with_one_line(tmp_path, monkeypatch):
    entry = next(m for m in SHIPPED if m["variant"] == "S" and m["scale"] == 4)
    copy = tmp_path / "models"
    shutil.copytree(models.models_dir(), copy)
    monkeypatch.setattr(models, "models_dir", lambda: copy)
    damaged = copy / entry["files"]["onnx"]
    data = bytearray(damaged.read_bytes())
    data[len(data) // 2] ^= 0xFF
    damaged.write_bytes(bytes(data))
    with pytest.raises(InputError, match="does not match the registry"):
        models.model_file("S", 4, "onnx")
    with pytest.raises(InputError, match="no shipped model for variant L at 16x"):
        models.model_file("L", 16)


SIZE = 192  # output width and height, pixels
FRAMES, SCORED = 8, 4  # an orbit of 8 frames at 2 degrees each; the last 4 are scored (history built up)
# dB on the scored frames, per model: the lowest measured (2026-11-23: XS 2x 31.49, XS 4x 25.39; 2026-11-29, the U-Nets
# retrained on the layered TAAU: S 2x 34.07, S 4x 28.57, M 4x 28.74, S 8x 23.40; bilinear 29.5-29.9, 23.0-23.6,
# 20.2-20.4) minus about 1 dB for other CPUs and library versions
PSNR_FLOOR = {"volsr-S-2x": 33.0, "volsr-S-4x": 27.5, "volsr-M-4x": 27.5, "volsr-S-8x": 22.4, "volsr-XS-2x": 30.5,
              "volsr-XS-4x": 24.4}


@pytest.fixture(scope="module")
def phantom_orbit():
    """The CT phantom under its preset, the cameras of a 2-degree-per-frame orbit filling the view, and
    an 8-spp native ground truth with jittered ray starts (seeds apart from the pipeline's)."""
    volume = Volume.from_record(make_phantom(shape=(96, 96, 96), spacing=(2.0, 2.0, 2.0)))
    tf = get_preset("CT-Phantom")
    caster = RayCaster(volume, tf, start_jitter="ign")
    cameras = orbit_around(caster.visible_bounds(), FRAMES, 2.0)
    truth = [render_supersampled(caster, c, SIZE, spp=8, seed=10**6 + 8 * t) for t, c in enumerate(cameras)]
    return volume, tf, caster, cameras, truth


SHIPPED_FILES = [(m, "onnx") for m in SHIPPED] + [(m, models.INT8_KIND) for m in SHIPPED if models.INT8_KIND in m["files"]]


@pytest.mark.parametrize("entry, kind", SHIPPED_FILES, ids=[m["files"][kind] for m, kind in SHIPPED_FILES])
def test_a_shipped_model_beats_bilinear_on_a_phantom_orbit(entry, kind, phantom_orbit):
    """Each shipped model's ONNX file (float32, and the 8-bit one where it ships) through the Pipeline (CPU) against
    the same LR size rendered at the pixel centres and stretched bilinearly (VTK's reduced-size rendering), on the same
    frames, above the model's floor."""
    volume, tf, caster, cameras, truth = phantom_orbit
    scale = entry["scale"]
    pipeline = Pipeline(volume, tf, models.model_file(entry["variant"], scale, kind), scale=scale,
                        size=(SIZE, SIZE), threads=2)
    bilinear = ReducedSize(caster, (SIZE, SIZE), scale, "bilinear")
    volsr_psnr, bilinear_psnr = [], []
    for t, camera in enumerate(cameras):
        upscaled, stretched = pipeline.render(camera), bilinear(camera).image
        if t >= FRAMES - SCORED:
            volsr_psnr.append(psnr_ssim(upscaled, truth[t], channel_axis=2)[0])
            bilinear_psnr.append(psnr_ssim(stretched, truth[t], channel_axis=2)[0])
    print(f"{entry['files'][kind]}: VolSR {np.round(volsr_psnr, 2)} dB, bilinear {np.round(bilinear_psnr, 2)} dB")
    assert all(v > b for v, b in zip(volsr_psnr, bilinear_psnr)), "VolSR must beat bilinear on every scored frame"
    assert min(volsr_psnr) >= PSNR_FLOOR[entry["name"]]
