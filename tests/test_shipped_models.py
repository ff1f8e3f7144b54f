"""The shipped models: registered, SHA-256 checked, small, and the ONNX and PyTorch files agree."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.runtime import models  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine  # noqa: E402
from volsr_core.runtime.export import example_inputs  # noqa: E402
from volsr_core.sr.checkpoint import load_model  # noqa: E402

SHIPPED = models.shipped_models()


def test_the_4x_model_of_variant_s_is_shipped():
    assert any(m["variant"] == "S" and m["scale"] == 4 for m in SHIPPED), "resources/models/models.json lists it"


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
