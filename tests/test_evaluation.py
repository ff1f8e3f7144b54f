"""`volsr eval`: metrics for the network and the baselines on the same frames, and the report files."""
from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from volsr_core.cli import main  # noqa: E402
from volsr_core.hashing import file_sha256  # noqa: E402
from volsr_core.sr.checkpoint import load_model, save_checkpoint  # noqa: E402
from volsr_core.apps.evaluate import METHODS, temporal_error  # noqa: E402
from volsr_core.sr.network import NetworkConfig, SuperResolutionNet  # noqa: E402
from volsr_core.errors import InputError  # noqa: E402


def test_temporal_error_is_zero_when_the_output_changes_like_the_truth():
    rng = np.random.default_rng(0)
    gt_prev, gt = rng.random((16, 16, 3)), rng.random((16, 16, 3))
    motion = np.zeros((16, 16, 2), np.float32)
    assert temporal_error(gt_prev + 0.1, gt + 0.1, gt_prev, gt, motion) == pytest.approx(0.0, abs=1e-9)
    flicker = temporal_error(gt_prev, gt + 0.2, gt_prev, gt, motion)
    assert flicker == pytest.approx(0.2, abs=1e-6)


def test_eval_writes_the_report_for_every_method(tiny_sequences, tmp_path, capsys):
    model = SuperResolutionNet(NetworkConfig(scale=4, previous_frames=2, fold=4, widths=(8, 12)))
    save_checkpoint(tmp_path / "model.pt", model)
    assert main(["eval", str(tmp_path / "model.pt"), "--data", str(tiny_sequences), "--out", str(tmp_path / "r")]) == 0
    printed = capsys.readouterr().out
    results = json.loads((tmp_path / "r" / "eval.json").read_text())
    expected = set(METHODS) - {"layered TAAU"}  # a version-2 store: every method but the base of a layered network
    assert set(results["overall"]) == expected == set(results["methods"])
    (video,) = results["videos"].values()  # the one test video, frame 2 (the first with 2 previous)
    assert video["frames"] == [2]
    for name in expected:
        assert len(video[name]["psnr"]) == 1 and 0 < video[name]["psnr"][0] < 100 and name in printed
    for name in ("eval.md", "psnr_per_frame.png", "methods.png", "crops.png"):
        assert (tmp_path / "r" / name).stat().st_size > 100
    assert "| **all** |" in (tmp_path / "r" / "eval.md").read_text()


def test_eval_of_the_onnx_file_gives_the_pytorch_models_numbers(tiny_sequences, tmp_path):
    """``volsr eval`` of a model's ONNX export (run by onnxruntime, as hosts run it) scores what its .pt scores."""
    pytest.importorskip("onnxruntime")
    from volsr_core.runtime.export import export_onnx

    model = SuperResolutionNet(NetworkConfig(scale=4, previous_frames=2, fold=4, widths=(8, 12)))
    save_checkpoint(tmp_path / "model.pt", model)
    export_onnx(model, tmp_path / "model.onnx")
    overall = {}
    for name in ("model.pt", "model.onnx"):
        assert main(["eval", str(tmp_path / name), "--data", str(tiny_sequences), "--out", str(tmp_path / f"report-{name}")]) == 0
        overall[name] = json.loads((tmp_path / f"report-{name}" / "eval.json").read_text())["overall"]
    assert overall["model.pt"].keys() == overall["model.onnx"].keys()
    for method, scores in overall["model.pt"].items():
        assert overall["model.onnx"][method]["psnr"] == pytest.approx(scores["psnr"], abs=1e-3), method


def test_model_files_load_only_when_they_are_what_they_claim(tmp_path):
    model = SuperResolutionNet(NetworkConfig(scale=2, previous_frames=1, fold=2, widths=(8, 12)))
    save_checkpoint(tmp_path / "m.pt", model, extra={"note": "test"})
    loaded = load_model(tmp_path / "m.pt", expected_sha256=file_sha256(tmp_path / "m.pt"))
    for a, b in zip(model.state_dict().values(), loaded.state_dict().values()):
        assert torch.equal(a, b)
    with pytest.raises(InputError, match="does not match"):
        load_model(tmp_path / "m.pt", expected_sha256="0" * 64)
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint at all")
    with pytest.raises(InputError, match="junk.pt: not a readable PyTorch checkpoint"):
        load_model(tmp_path / "junk.pt")
    torch.save({"weights": torch.zeros(3)}, tmp_path / "foreign.pt")
    with pytest.raises(InputError, match="foreign.pt: not a VolSR model"):
        load_model(tmp_path / "foreign.pt")
