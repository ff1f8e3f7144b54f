"""Variant XS's base filter: the CPU kernel against the network (PyTorch) and its ONNX graph, the
upscaler's path through the kernel against the generic one, and the closed-form fit against a known
filter and against the identity it starts as."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.runtime.base_filter import FILTER_KEY, filter_image  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine  # noqa: E402
from volsr_core.runtime.export import example_inputs, export_onnx  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.scene import Volume, get_preset  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402
from volsr_core.sr.least_squares import fit_base_filter, is_closed_form  # noqa: E402
from volsr_core.sr.network import BaseFilter, SuperResolutionNet, variant_config  # noqa: E402


def random_filter(net: SuperResolutionNet, seed: int = 0) -> SuperResolutionNet:
    """``net`` with a random sharpening-like base filter (not the identity it starts as)."""
    g = torch.Generator().manual_seed(seed)
    conv = net.base_filter.conv
    with torch.no_grad():
        conv.weight.add_(0.1 * torch.randn(conv.weight.shape, generator=g))
        conv.bias.copy_(0.01 * torch.randn(3, generator=g))
    return net.eval()


@pytest.mark.parametrize("kernel", (5, 9))
def test_the_cpu_kernel_computes_what_the_network_filter_does(kernel):
    """Values outside [0, 1] are clipped first and the border repeats its edge pixels, as in BaseFilter."""
    g = torch.Generator().manual_seed(kernel)
    layer = BaseFilter(kernel)
    with torch.no_grad():
        layer.conv.weight.copy_(torch.randn(layer.conv.weight.shape, generator=g))
        layer.conv.bias.copy_(torch.randn(3, generator=g))
        image = torch.rand(1, 3, 37, 29, generator=g) * 1.6 - 0.3
        expected = layer(torch.clamp(image, 0, 1))[0].numpy().transpose(1, 2, 0)
    weights, bias = layer.conv.weight[:, 0].detach().numpy(), layer.conv.bias.detach().numpy()
    got = filter_image(image[0].numpy().transpose(1, 2, 0), weights, bias)
    assert got.shape == (37, 29, 3) and np.abs(got - expected).max() < 1e-5


def test_an_xs_model_runs_its_filter_in_the_kernel_and_agrees_with_its_onnx_graph(tmp_path):
    net = random_filter(SuperResolutionNet(variant_config("XS", 4, taau_base=True)))
    engine = OnnxEngine(export_onnx(net, tmp_path / "xs.onnx"), providers=["CPUExecutionProvider"])
    assert engine.base_filter is not None and is_closed_form(net)
    lr, motion, jitter, history = (x.numpy() for x in example_inputs(net.config, 9, 7))
    history = history * 1.4 - 0.2
    graph = engine.session.run(None, {name: value for name, value in
                                      {"lr": lr, "motion": motion, "jitter": jitter, "history": history}.items()
                                      if name in engine.input_names})[0]
    assert np.abs(engine(lr, motion, jitter, history) - graph).max() < 1e-5
    s_model = SuperResolutionNet(variant_config("S", 4, 0, taau_base=True, taau_aux=True))
    assert OnnxEngine(export_onnx(s_model, tmp_path / "s.onnx"), providers=["CPUExecutionProvider"]).base_filter is None


def test_damaged_filter_weights_in_the_metadata_are_a_one_line_error(tmp_path):
    onnx = pytest.importorskip("onnx")
    path = export_onnx(SuperResolutionNet(variant_config("XS", 2, taau_base=True)), tmp_path / "xs.onnx")
    graph = onnx.load(path)
    (entry,) = [e for e in graph.metadata_props if e.key == FILTER_KEY]
    entry.value = json.dumps({"weights": [[[1.0]]], "bias": [0.0, 0.0, 0.0]})
    onnx.save(graph, path)
    with pytest.raises(InputError) as caught:
        OnnxEngine(path, providers=["CPUExecutionProvider"])
    assert str(caught.value) == (f"{path}: {FILTER_KEY}: expected finite weights of shape (3, 5, 5) and 3 biases, "
                                 "got (1, 1, 1) and (3,)")


def test_the_upscaler_makes_the_same_frames_through_the_kernel_as_through_the_graph(tmp_path):
    """Pipeline over a phantom orbit: XS through its CPU kernel (the upscaler's own path, no network
    inputs) against the same model's ONNX graph fed as every other network is."""
    net = random_filter(SuperResolutionNet(variant_config("XS", 2, taau_base=True)))
    path = export_onnx(net, tmp_path / "xs.onnx")
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48), spacing=(2.0, 2.0, 2.0)))
    runs = []
    for through_kernel in (True, False):
        pipeline = Pipeline(volume, get_preset("CT-Phantom"), path, scale=2, size=(64, 48), threads=2)
        if not through_kernel:
            pipeline.upscaler.base_filter = pipeline.engine.base_filter = None
        cameras = orbit_around(pipeline.caster.visible_bounds(), 4, 3.0)
        runs.append([pipeline.render(camera) for camera in cameras])
    for kernel_frame, graph_frame in zip(*runs):
        assert kernel_frame.shape == (48, 64, 3) and np.abs(kernel_frame - graph_frame).max() < 1e-5


class FrameSet:
    """A list of dataset items as :class:`~volsr_core.sr.loader.SequenceDataset` gives them."""

    def __init__(self, items: list[dict[str, torch.Tensor]]):
        self.items = items

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        return self.items[index]


def test_the_least_squares_fit_recovers_a_known_filter():
    """Targets made by a known filter of the base (TAAU's estimate here) give back that filter."""
    g = torch.Generator().manual_seed(1)
    truth = random_filter(SuperResolutionNet(variant_config("XS", 2, taau_base=True)), seed=3)
    items = []
    for _ in range(3):
        history = torch.rand(1, 3, 24, 20, generator=g)
        with torch.no_grad():
            hr = truth(torch.zeros(1, 1, 8, 12, 10), torch.zeros(1, 1, 2, 12, 10), torch.zeros(1, 1, 2), history)[0]
        items.append({"lr": torch.zeros(1, 8, 12, 10), "taau": history, "hr": hr, "jitter": torch.zeros(1, 2)})
    fitted = SuperResolutionNet(variant_config("XS", 2, taau_base=True))
    assert fit_base_filter(fitted, FrameSet(items), progress=False) == 3 * 24 * 20
    assert torch.allclose(fitted.base_filter.conv.weight, truth.base_filter.conv.weight, atol=1e-4)
    assert torch.allclose(fitted.base_filter.conv.bias, truth.base_filter.conv.bias, atol=1e-4)


def test_volsr_train_fits_an_xs_model_no_worse_than_the_identity_on_its_training_frames(tiny_sequences, tmp_path):
    """`volsr train` with an XS config solves for the filter; the identity (TAAU unchanged) is one of the
    filters it chose among, so on the frames it was fitted to its squared error cannot be larger."""
    from volsr_core.cli import main
    from volsr_core.sr.checkpoint import load_model
    from volsr_core.sr.least_squares import item_inputs
    from volsr_core.sr.loader import SequenceDataset

    config = {"seed": 0, "out": str(tmp_path / "run"), "data": {"root": str(tiny_sequences), "scale": 4,
              "previous_frames": 0}, "model": {"variant": "XS", "taau_base": True}, "optim": {}, "train": {},
              "loss": {}}
    (tmp_path / "xs.yaml").write_text(yaml.safe_dump(config))
    assert main(["train", str(tmp_path / "xs.yaml")]) == 0
    fitted = load_model(Path(tmp_path / "run" / "best.pt")).eval()
    assert fitted.config.base_kernel == 9 and (tmp_path / "run" / "log.csv").is_file()
    frames = SequenceDataset(tiny_sequences, "train", 4, 0, None, augment=False, taau=fitted.config)
    errors = {"fitted": 0.0, "identity": 0.0}
    with torch.no_grad():
        for i in range(len(frames)):
            item = frames[i]
            lr, history = item_inputs(item)
            base = fitted.unfiltered_base(lr, history)[0]
            errors["identity"] += float(torch.sum((base - item["hr"]) ** 2))
            errors["fitted"] += float(torch.sum((fitted.base_filter(base[None])[0] - item["hr"]) ** 2))
    assert errors["fitted"] <= errors["identity"] * (1 + 1e-4)
