"""Variant XS's base filter: the CPU kernel against the network (PyTorch) and its ONNX graph, the
upscaler's path through the kernel against the generic one, and the closed-form fit against a known
filter and against the identity it starts as."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.render.features import FeatureFrame  # noqa: E402
from volsr_core.render.layout import OUT_CHANNELS  # noqa: E402
from volsr_core.runtime.base_filter import BAND_ROWS, FILTER_KEY, Scratch, filter_image  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine, TorchEngine  # noqa: E402
from volsr_core.runtime.export import example_inputs, export_onnx  # noqa: E402
from volsr_core.runtime.models import model_file  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.runtime.upscaler import StatefulUpscaler  # noqa: E402
from volsr_core.scene.camera import Camera  # noqa: E402
from volsr_core.scene import Volume, get_preset  # noqa: E402
from volsr_core.scene.camera_paths import orbit_around  # noqa: E402
from volsr_core.sr.least_squares import fit_base_filter, is_closed_form  # noqa: E402
from volsr_core.sr.network import BaseFilter, SuperResolutionNet, variant_config  # noqa: E402
from volsr_core.temporal.resample import resize_bicubic  # noqa: E402
from volsr_core.temporal.taau import TemporalUpsampler, view_rotation  # noqa: E402


def random_filter(net: SuperResolutionNet, seed: int = 0) -> SuperResolutionNet:
    """``net`` with a random sharpening-like base filter (not the identity it starts as)."""
    g = torch.Generator().manual_seed(seed)
    conv = net.base_filter.conv
    with torch.no_grad():
        conv.weight.add_(0.1 * torch.randn(conv.weight.shape, generator=g))
        conv.bias.copy_(0.01 * torch.randn(conv.bias.shape, generator=g))
    return net.eval()


@pytest.mark.parametrize("kernel, orientations", [(5, 1), (9, 1), (5, 2)])
def test_the_cpu_kernel_computes_what_the_network_filter_does(kernel, orientations):
    """Values outside [0, 1] are clipped first and the border repeats its edge pixels, as in BaseFilter; a pair
    picks each pixel's filter by the same orientation test."""
    g = torch.Generator().manual_seed(kernel)
    layer = BaseFilter(kernel, orientations)
    with torch.no_grad():
        layer.conv.weight.copy_(torch.randn(layer.conv.weight.shape, generator=g))
        layer.conv.bias.copy_(torch.randn(layer.conv.bias.shape, generator=g))
        image = torch.nn.functional.interpolate(torch.rand(1, 3, 10, 8, generator=g), size=(37, 29), mode="bicubic")
        image = image * 1.6 - 0.3
        expected = layer(torch.clamp(image, 0, 1))[0].numpy().transpose(1, 2, 0)
    weights, bias = (w.numpy() for w in layer.weights())
    assert weights.shape == (orientations, 3, kernel, kernel) and bias.shape == (orientations, 3)
    got = filter_image(image[0].numpy().transpose(1, 2, 0), weights, bias)
    assert got.shape == (37, 29, 3) and np.abs(got - expected).max() < 1e-5


@pytest.mark.parametrize("orientations", [1, 2])
def test_the_kernel_filters_band_by_band_and_sums_once_where_a_row_end_is_one_colour(orientations):
    """An image several bands tall (the last one short) with the background either side of a volume: one colour on
    the left, another on the right, a black top; where every tap of a pixel reads one colour the kernel sums once per
    row end, elsewhere each pixel: against the network's filter everywhere, band edges and flat ends included."""
    g = torch.Generator().manual_seed(3 + orientations)
    layer = BaseFilter(5, orientations)
    height, width = 2 * BAND_ROWS + 11, 61
    with torch.no_grad():
        layer.conv.weight.copy_(torch.randn(layer.conv.weight.shape, generator=g))
        layer.conv.bias.copy_(torch.randn(layer.conv.bias.shape, generator=g))
        image = torch.nn.functional.interpolate(torch.rand(1, 3, 9, 7, generator=g), size=(height, width),
                                                mode="bicubic")
        image[..., :, :17] = torch.tensor([0.2, 0.4, 0.9]).view(1, 3, 1, 1)
        image[..., :, 40:] = torch.tensor([0.7, 0.1, 0.0]).view(1, 3, 1, 1)
        image[..., :BAND_ROWS + 3, :] = 0.0
        image[..., BAND_ROWS + 20, 30] = 1.5  # one bright pixel, clipped
        expected = layer(torch.clamp(image, 0, 1))[0].numpy().transpose(1, 2, 0)
    got = filter_image(image[0].numpy().transpose(1, 2, 0), *(w.numpy() for w in layer.weights()))
    assert np.abs(got - expected).max() < 1e-5


@pytest.mark.parametrize("overrides, expected", [({}, (9, 1)), ({"base_kernel": 5, "base_orientations": 2}, (5, 2))])
def test_a_training_config_overrides_the_variants_base_filter(overrides, expected):
    from volsr_core.sr.config import TrainingConfig
    from volsr_core.sr.training import build_model

    config = TrainingConfig.from_dict({"data": {"root": ".", "scale": 4, "previous_frames": 0},
                                       "model": {"variant": "XS", "taau_base": True, **overrides}})
    net = build_model(config).config
    assert (net.base_kernel, net.base_orientations) == expected
    assert build_model(config).base_filter.orientations == expected[1]


@pytest.mark.parametrize("direction, second", [(1.0, 0.0), (-1.0, 1.0)])
def test_a_pair_takes_its_second_filter_on_edges_running_from_top_left_to_bottom_right(direction, second):
    """Stripes of constant x + y run from top right to bottom left (first filter), of constant x - y from top
    left to bottom right (second), in the network and in the kernel alike."""
    y, x = np.mgrid[0:40, 0:36].astype(np.float32)
    stripes = 0.5 + 0.4 * np.sin(0.5 * (x + direction * y))
    image = np.repeat(stripes[..., None], 3, axis=2)
    layer = BaseFilter(5, 2)
    with torch.no_grad():
        layer.conv.weight[1::2].zero_()  # the second filter of each channel gives its bias: 1
        layer.conv.bias.copy_(torch.tensor([0.0, 1.0] * 3))
        network = layer(torch.from_numpy(image.transpose(2, 0, 1).copy())[None])[0].numpy().transpose(1, 2, 0)
    kernel = filter_image(image, *(w.numpy() for w in layer.weights()))
    for out in (network, kernel):
        assert np.isclose(out, 1.0).mean() == second


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
    assert OnnxEngine(model_file("S", 4), providers=["CPUExecutionProvider"]).base_filter is None  # a U-Net's file
    # the kernel whatever the providers (a GPU one is refused here: onnxruntime falls back to the CPU), and from torch
    with warnings.catch_warnings():  # onnxruntime warns of the provider it does not have
        warnings.simplefilter("ignore", UserWarning)
        gpu_first = OnnxEngine(tmp_path / "xs.onnx", providers=["CUDAExecutionProvider", "CPUExecutionProvider"])
    assert gpu_first.base_filter is not None
    for got, want in zip(TorchEngine(net).base_filter, engine.base_filter):
        assert got.shape == want.shape and np.abs(got - want).max() < 1e-6
    assert TorchEngine(s_model).base_filter is None


def test_damaged_filter_weights_in_the_metadata_are_a_one_line_error(tmp_path):
    onnx = pytest.importorskip("onnx")
    path = export_onnx(SuperResolutionNet(variant_config("XS", 2, taau_base=True)), tmp_path / "xs.onnx")
    graph = onnx.load(path)
    (entry,) = [e for e in graph.metadata_props if e.key == FILTER_KEY]
    entry.value = json.dumps({"weights": [[[1.0]]], "bias": [0.0, 0.0, 0.0]})
    onnx.save(graph, path)
    with pytest.raises(InputError) as caught:
        OnnxEngine(path, providers=["CPUExecutionProvider"])
    assert str(caught.value) == (f"{path}: {FILTER_KEY}: expected finite weights of shape (2, 3, 5, 5) and biases "
                                 "of shape (2, 3), got (1, 1, 1) and (3,)")


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


def test_an_xs_pipeline_in_depth_slabs_filters_the_layered_taau_estimate(tmp_path):
    """Pipeline(slabs=K): frames rendered in K depth slabs, the layered TAAU's estimate (over the pipeline's
    background, told the frame's pixels per voxel) through XS's filter; a U-Net not trained on slabs takes none."""
    from volsr_core.temporal.layered import LayeredUpsampler
    from volsr_core.temporal.taau import view_rotation

    net = random_filter(SuperResolutionNet(variant_config("XS", 2, taau_base=True)))
    path = export_onnx(net, tmp_path / "xs.onnx")
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48), spacing=(2.0, 2.0, 2.0)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), path, scale=2, size=(64, 48), threads=2, slabs=3,
                        background=(0.1, 0.2, 0.3))
    layered, previous = LayeredUpsampler(2), None
    for camera in orbit_around(pipeline.caster.visible_bounds(), 4, 3.0):
        image = pipeline.render(camera)
        lr = pipeline.last_low_resolution
        assert lr.slabs.shape == (3, 24, 32, 6)
        estimate = layered(lr.slabs, lr.jitter, (0.1, 0.2, 0.3), view_rotation(camera, previous), lr.pixels_per_voxel)
        expected = np.clip(filter_image(estimate, *pipeline.engine.base_filter), 0.0, 1.0)
        assert np.abs(image - expected).max() < 1e-6
        previous = camera
    one_layer = SuperResolutionNet(variant_config("S", 2, 0, taau_base=True))  # every shipped U-Net takes slabs
    with pytest.raises(ValueError, match="depth slabs"):
        Pipeline(volume, get_preset("CT-Phantom"), one_layer, scale=2, slabs=2)


def test_the_shipped_xs_4x_runs_its_filter_in_the_kernel_on_its_depth_slabs_from_either_file():
    """volsr-XS-4x.pt (torch) hands its filter to the CPU kernel as the .onnx does, and both run on the two depth slabs
    the filter was fitted on: the same images. Through its graph instead (an engine without the kernel's weights,
    as ONNX files without them run) it still refines the layered TAAU: the same images again; with slabs=0 (the
    TAAU) they differ."""
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48), spacing=(2.0, 2.0, 2.0)))
    runs = {}
    for name, kind, slabs in (("onnx", "onnx", None), ("pt", "pt", None), ("pt graph", "pt", None),
                              ("pt graph, TAAU", "pt", 0)):
        pipeline = Pipeline(volume, get_preset("CT-Phantom"), model_file("XS", 4, kind), scale=4, size=(64, 48),
                            threads=2, slabs=slabs)
        assert pipeline.engine.base_filter is not None and pipeline.slabs == (2 if slabs is None else 0)
        if "graph" in name:
            pipeline.upscaler.base_filter = pipeline.engine.base_filter = None
        cameras = orbit_around(pipeline.caster.visible_bounds(), 4, 3.0)
        runs[name] = np.stack([pipeline.render(camera) for camera in cameras])
    assert np.abs(runs["pt"] - runs["onnx"]).max() < 1e-5
    assert np.abs(runs["pt graph"] - runs["onnx"]).max() < 1e-5
    assert np.abs(runs["pt graph, TAAU"] - runs["onnx"]).max() > 0.02


def test_xs_at_4x_and_more_runs_in_two_depth_slabs_unless_told_otherwise(tmp_path):
    """The default slabs (None): those an XS model was fitted on (``taau_slabs``, read from the ONNX file), else two
    for XS on TAAU at 4x and 8x, none for XS 2x, XS on the bilinear upscale or a U-Net model; slabs=0 gives the
    TAAU on the frame's colour; a negative count is refused."""
    from volsr_core.runtime.engines import open_engine
    from volsr_core.runtime.upscaler import default_slabs

    cases = {"xs4": (variant_config("XS", 4, taau_base=True), 2), "xs8": (variant_config("XS", 8, taau_base=True), 2),
             "xs2": (variant_config("XS", 2, taau_base=True), 0),
             "xs2fitted3": (variant_config("XS", 2, taau_base=True, taau_slabs=3), 3),  # the slabs it was fitted on
             "xs4bilinear": (variant_config("XS", 4), 0),
             "s4": (variant_config("S", 4, taau_base=True), 0)}
    for name, (config, slabs) in cases.items():  # the slabs it was fitted on read from its ONNX file, the rest in torch
        model = SuperResolutionNet(config)
        engine = open_engine(export_onnx(model, tmp_path / f"{name}.onnx") if name == "xs2fitted3" else model)
        assert default_slabs(engine) == slabs, name
        assert StatefulUpscaler(engine).slabs == slabs and StatefulUpscaler(engine, slabs=0).slabs == 0
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48), spacing=(2.0, 2.0, 2.0)))
    for slabs, rendered in ((None, (2, 16, 16, 6)), (0, None)):  # the shipped XS 4x
        pipeline = Pipeline(volume, get_preset("CT-Phantom"), scale=4, size=(64, 64), threads=2, slabs=slabs)
        assert pipeline.render(Camera.framing(pipeline.caster.visible_bounds())).shape == (64, 64, 3)
        lr_slabs = pipeline.last_low_resolution.slabs
        assert (lr_slabs if lr_slabs is None else lr_slabs.shape) == rendered
    with pytest.raises(ValueError, match="0 or more"):
        Pipeline(volume, get_preset("CT-Phantom"), scale=4, slabs=-1)


def test_an_output_clipped_in_the_kernel_equals_the_output_clipped_after_it():
    """``clip_output``: the one pass that writes the image clips it, as np.clip after it would (one filter and a pair,
    weights that overshoot [0, 1])."""
    rng = np.random.default_rng(7)
    image = rng.random((23, 19, 3), dtype=np.float32)
    weights, bias = rng.normal(0, 0.4, (2, 3, 5, 5)).astype(np.float32), rng.normal(0, 0.3, (2, 3)).astype(np.float32)
    for n in (1, 2):
        plain = filter_image(image, weights[:n], bias[:n])
        assert plain.min() < 0.0 and plain.max() > 1.0, "the weights must overshoot for the test to mean something"
        assert np.array_equal(filter_image(image, weights[:n], bias[:n], clip_output=True), np.clip(plain, 0.0, 1.0))


def test_a_filter_that_stretches_by_two_makes_the_filtered_image_stretched_bicubically():
    """``stretch=2``: the bands double their rows as they filter them and the rows are mixed after, which gives
    resize_bicubic's stretch of the filtered image, clipped as it is (one filter and a pair, clipped and not, a height
    of several bands and one of a few rows, the second frame through kept work buffers); other stretches are refused."""
    rng = np.random.default_rng(11)
    weights, bias = rng.normal(0, 0.4, (2, 3, 5, 5)).astype(np.float32), rng.normal(0, 0.3, (2, 3)).astype(np.float32)
    scratch = Scratch()
    for shape in ((2 * BAND_ROWS + 7, 21, 3), (5, 9, 3), (5, 9, 3)):
        image = rng.random(shape, dtype=np.float32)
        for n in (1, 2):
            for clip in (False, True):
                filtered = filter_image(image, weights[:n], bias[:n], clip_output=clip)
                expected = resize_bicubic(filtered, 2 * shape[1], 2 * shape[0], a=-0.75,
                                          clamp=(0.0, 1.0) if clip else None)
                stretched = filter_image(image, weights[:n], bias[:n], scratch=scratch, clip_output=clip, stretch=2,
                                         stretch_a=-0.75)
                assert stretched.shape == (2 * shape[0], 2 * shape[1], 3)
                np.testing.assert_allclose(stretched, expected, atol=1e-6)
        assert not clip or (expected.min() == 0.0 and expected.max() == 1.0), "the stretch's clip is tested"
    with pytest.raises(ValueError, match="stretch"):
        filter_image(image, weights, bias, stretch=3)


def test_work_buffers_kept_between_frames_change_no_result():
    rng = np.random.default_rng(5)
    weights, bias = rng.normal(0, 0.2, (2, 3, 5, 5)).astype(np.float32), rng.normal(0, 0.1, (2, 3)).astype(np.float32)
    scratch = Scratch()
    for shape in ((20, 18, 3), (20, 18, 3), (11, 13, 3)):
        image = rng.random(shape, dtype=np.float32)
        assert np.array_equal(filter_image(image, weights, bias, scratch=scratch), filter_image(image, weights, bias))
        assert np.array_equal(filter_image(image, weights[:1], bias[:1], scratch=scratch),
                              filter_image(image, weights[:1], bias[:1]))


def test_an_xs_model_told_the_fineness_filters_the_smoothed_taau_and_an_older_one_the_plain_one(tmp_path):
    """Frames 3 output pixels per voxel fine while the view rotates: XS 2x (told, as trained) filters what TAAU
    told the frame's pixels per voxel makes; an XS model without ``taau_fine_sampling`` what TAAU untold makes.
    Both start as the identity, so each upscaler's output is its TAAU's estimate."""
    paths = {told: export_onnx(SuperResolutionNet(variant_config("XS", 2, taau_base=True, taau_fine_sampling=told)),
                               tmp_path / f"xs-{told}.onnx") for told in (True, False)}
    upscalers = {told: StatefulUpscaler(OnnxEngine(path, providers=["CPUExecutionProvider"]))
                 for told, path in paths.items()}
    assert all(u.base_filter is not None for u in upscalers.values())
    references = {True: TemporalUpsampler(2), False: TemporalUpsampler(2)}
    rng = np.random.default_rng(6)
    cameras = [Camera(position=np.array([np.sin(a), 0.0, np.cos(a)])) for a in np.radians([0.0, 2.0, 4.0])]
    for k, camera in enumerate(cameras):
        data = rng.random((9, 8, OUT_CHANNELS), dtype=np.float32)
        previous = cameras[k - 1] if k else None
        frame = FeatureFrame(data, camera, jitter=(0.2 * k - 0.3, 0.1), previous_camera=previous,
                             pixels_per_voxel=1.5)
        frame.motion[...] = 0.0 if k == 0 else 0.4
        outs = {}
        for told, upscaler in upscalers.items():
            expected = references[told](frame.color, frame.motion, frame.jitter, frame.motion_depth,
                                        view_rotation(camera, previous), 1.5 if told else None)
            outs[told] = upscaler.upscale(frame)
            assert np.abs(outs[told] - np.clip(expected, 0, 1)).max() < 1e-5
        assert k == 0 or np.abs(outs[True] - outs[False]).max() > 1e-2


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


def test_volsr_train_fits_xs_on_the_layered_taau_and_without_a_bias_black_stays_black(tiny_layered_sequences,
                                                                                      tiny_sequences, tmp_path):
    """A config with ``taau_slabs`` fits the filter on the layered TAAU's estimate of the dataset's depth slabs (the
    loader's base is that estimate, and the fit beats the identity on it); ``fit_bias: false`` keeps the bias 0;
    ``volsr eval`` scores the layered TAAU beside VolSR; a dataset without slabs is a one-line error naming its
    store."""
    import h5py

    from volsr_core.apps.evaluate import evaluate
    from volsr_core.cli import main
    from volsr_core.dataset.store import frame_pixels_per_voxel, view_rotations
    from volsr_core.sr.checkpoint import load_model
    from volsr_core.sr.least_squares import item_inputs
    from volsr_core.sr.loader import SequenceDataset
    from volsr_core.temporal.layered import LayeredUpsampler

    config = {"seed": 0, "out": str(tmp_path / "run"),
              "data": {"root": str(tiny_layered_sequences), "scale": 4, "previous_frames": 0},
              "model": {"variant": "XS", "taau_base": True, "taau_slabs": 2, "base_kernel": 5}, "optim": {},
              "train": {"fit_bias": False}, "loss": {}}
    (tmp_path / "xs.yaml").write_text(yaml.safe_dump(config))
    assert main(["train", str(tmp_path / "xs.yaml")]) == 0
    fitted = load_model(Path(tmp_path / "run" / "best.pt")).eval()
    assert (fitted.config.taau_slabs, fitted.config.base_kernel) == (2, 5)
    assert torch.count_nonzero(fitted.base_filter.conv.bias) == 0
    assert torch.count_nonzero(fitted.base_filter.conv.weight) == fitted.base_filter.conv.weight.numel()
    frames = SequenceDataset(tiny_layered_sequences, "train", 4, 0, None, augment=False, taau=fitted.config)
    video = frames.videos[0]
    with h5py.File(tiny_layered_sequences / video["file"], "r") as h5:
        slabs, jitter, turns = h5["lr4/slabs"][()], h5["lr4/jitter"][()], view_rotations(h5["cameras"][()])
    fineness = frame_pixels_per_voxel(video, slabs.shape[2])
    layered = LayeredUpsampler(4)  # told the pixels per voxel, as the upscaler tells it
    estimates = [layered(slabs[t], tuple(jitter[t]), rotation=turns[t], pixels_per_voxel=fineness[t])
                 for t in range(len(slabs))]
    errors = {"fitted": 0.0, "identity": 0.0}
    with torch.no_grad():
        for i, (_, t) in enumerate(frames.samples):
            item = frames[i]
            lr, history = item_inputs(item)
            base = fitted.unfiltered_base(lr, history)[0]
            if i < len(estimates):  # the first video: the loader's base is the layered TAAU's estimate (float16)
                expected = np.clip(estimates[t], 0, 1).transpose(2, 0, 1)
                assert np.abs(base.numpy() - expected).max() < 2e-3
            errors["identity"] += float(torch.sum((base - item["hr"]) ** 2))
            errors["fitted"] += float(torch.sum((fitted.base_filter(base[None])[0] - item["hr"]) ** 2))
    assert errors["fitted"] <= errors["identity"] * (1 + 1e-4)
    results, _ = evaluate(fitted, tiny_layered_sequences, "test", progress=False)
    assert results["methods"] == ["bilinear", "bilinear, jittered", "bicubic, jittered", "TAAU", "layered TAAU",
                                  "VolSR"]
    assert results["overall"]["layered TAAU"]["psnr"] != results["overall"]["TAAU"]["psnr"]
    with pytest.raises(InputError, match=r"v000\d\.h5: holds 0 depth slabs at 4x \(lr4/slabs\), the network refines "
                                         r"the layered TAAU of 2: make the dataset with `slabs: 2`"):
        SequenceDataset(tiny_sequences, "train", 4, 0, None, augment=False, taau=fitted.config)


@pytest.mark.parametrize("orientations, stretch", [(1, 1), (2, 1), (1, 2), (2, 2)])
def test_a_filter_told_where_the_image_is_one_colour_around_makes_the_image_it_makes_of_it_whole(orientations,
                                                                                                 stretch):
    """``window``: the kernels run on the window widened by the filter's reach alone and the rest of the output takes
    what the filter makes of the colour around it; the same image as filtering it whole, to float rounding (windows
    inside the image, at its edges, empty and whole; clipped and not; one work buffer set for windows of every
    size)."""
    rng = np.random.default_rng(20 + orientations)
    weights = rng.normal(0, 0.2, (orientations, 3, 5, 5)).astype(np.float32)
    weights[:, :, 2, 2] += 1.0
    bias = rng.normal(0, 0.05, (orientations, 3)).astype(np.float32)
    scratch = Scratch()
    height, width = 2 * BAND_ROWS + 9, 70
    for window in ((20, 50, 30, 60), (0, 30, 0, width), (40, height, 50, width), (30, 30, 9, 9), (0, height, 0, width),
                   (3, height - 2, 1, width - 3)):
        image = np.empty((height, width, 3), np.float32)
        image[:] = (0.2, 0.45, 0.8)
        top, bottom, left, right = window
        image[top:bottom, left:right] = rng.random((bottom - top, right - left, 3)) * 1.4 - 0.2
        for clip in (True, False):
            whole = filter_image(image, weights, bias, clip_output=clip, stretch=stretch, stretch_a=-0.75)
            windowed = filter_image(image, weights, bias, scratch=scratch, clip_output=clip, stretch=stretch,
                                    stretch_a=-0.75, window=window)
            assert windowed.shape == whole.shape and np.abs(windowed - whole).max() <= 1e-6


@pytest.mark.parametrize("slabs, stretch", [(0, 1), (0, 2), (2, 1), (2, 2)])
def test_an_xs_upscaler_filters_its_taau_estimate_where_it_is_not_the_background_alone(tmp_path, slabs, stretch):
    """The upscaler passes the filter the window its TAAU knows its estimate to be the background outside (one layer
    or in depth slabs, the image stretched or not, on a light background): the same frames, to float rounding, as the
    filter run on the whole estimate, and the window leaves out much of the frame."""
    net = random_filter(SuperResolutionNet(variant_config("XS", 2, taau_base=True)))
    path = export_onnx(net, tmp_path / "xs.onnx")
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48), spacing=(2.0, 2.0, 2.0)))
    runs, windows = [], []
    for windowed in (True, False):
        pipeline = Pipeline(volume, get_preset("CT-Phantom"), path, scale=2 * stretch, size=(96, 80), threads=2,
                            slabs=slabs, stretch=stretch, background=(0.76, 0.76, 0.87))
        taau = pipeline.upscaler.history.taau
        if not windowed:
            taau.background_window = lambda: None
        cameras = orbit_around(pipeline.caster.visible_bounds(), 5, 2.0, aspect=96 / 80, fill=0.5)
        frames = []
        for camera in cameras:
            frames.append(pipeline.render(camera))
            if windowed:
                windows.append(taau.background_window())
        runs.append(frames)
    for with_window, whole in zip(*runs):
        assert np.abs(with_window - whole).max() <= 1e-6
    lr_w, lr_h = 96 // (2 * stretch), 80 // (2 * stretch)
    shares = [(b - t) * (r - l) / (4 * lr_w * lr_h) for t, b, l, r in windows]
    assert max(shares) < 0.8, f"the phantom fills {shares} of the frame: the window is not tested"
