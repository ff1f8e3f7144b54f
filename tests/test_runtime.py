"""Runtime: ONNX export round trip, engines, the stateful upscaler's history, the pipeline."""
from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnxruntime")

from volsr_core.errors import InputError  # noqa: E402
from volsr_core.render.features import FeatureFrame  # noqa: E402
from volsr_core.render.layout import OUT_CHANNELS  # noqa: E402
from volsr_core.runtime.engines import OnnxEngine, TorchEngine, choose_providers  # noqa: E402
from volsr_core.runtime.export import example_inputs, export_onnx  # noqa: E402
from volsr_core.runtime.upscaler import StatefulUpscaler, _motion_statistics  # noqa: E402
from volsr_core.scene.camera import Camera  # noqa: E402
from volsr_core.sr.network import SuperResolutionNet, variant_config  # noqa: E402


def perturbed(config):
    """A network whose every weight matters (the default init leaves some paths near zero)."""
    torch.manual_seed(0)
    net = SuperResolutionNet(config).eval()
    with torch.no_grad():
        for p in net.parameters():
            p.add_(torch.randn_like(p) * 0.05)
    return net


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``exported(config)``: the ONNX file of :func:`perturbed` ``config`` (the same weights every time), written
    once per module: an export takes 15-30 s on the 2-core machine."""
    files = {}

    def export(config):
        key = json.dumps(config.to_dict(), sort_keys=True)
        if key not in files:
            files[key] = export_onnx(perturbed(config), tmp_path_factory.mktemp("exported") / "m.onnx",
                                     example_size=(8, 12))
        return files[key]

    return export


@pytest.mark.parametrize("variant, scale, previous, recurrent, taau", [
    ("S", 4, 2, False, False), ("S", 4, 0, True, False), ("M", 2, 1, True, False), ("S", 8, 1, False, False),
    ("S", 4, 0, False, True)])
def test_onnx_matches_torch_at_a_size_other_than_the_export_one(exported, variant, scale, previous, recurrent, taau):
    net = perturbed(variant_config(variant, scale, previous, recurrent=recurrent, taau_base=taau))
    path = exported(net.config)  # exported at 8 x 12 LR pixels
    engine = OnnxEngine(path, providers=["CPUExecutionProvider"])
    assert engine.config == net.config
    inputs = example_inputs(net.config, 13, 10, batch=2)
    with torch.no_grad():
        expected = net(*inputs).numpy()
    got = engine(*(x.numpy() for x in inputs))
    assert got.shape == (2, 3, 13 * scale, 10 * scale)
    assert np.abs(got - expected).max() <= 1e-4
    if recurrent or taau:  # no history given: both stand in the upscaled colour
        with torch.no_grad():
            first = net(*inputs[:3]).numpy()
        assert np.abs(engine(*(x.numpy() for x in inputs[:3])) - first).max() <= 1e-4


def test_provider_order_prefers_tensorrt_then_cuda_then_cpu():
    assert choose_providers(["CPUExecutionProvider", "CUDAExecutionProvider", "TensorrtExecutionProvider"]) == [
        "TensorrtExecutionProvider", "CUDAExecutionProvider", "CPUExecutionProvider"]
    assert choose_providers(["CPUExecutionProvider"]) == ["CPUExecutionProvider"]


def test_foreign_and_damaged_onnx_files_give_one_line_errors(tmp_path):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(InputError, match="junk.onnx: not a loadable ONNX model"):
        OnnxEngine(junk)
    plain = tmp_path / "plain.onnx"
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "plain",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)], ir_version=8), str(plain))
    with pytest.raises(InputError, match="without VolSR metadata"):
        OnnxEngine(plain)


def feature_frame(rng, h=6, w=5, jitter=(0.1, -0.2), motion=0.0):
    data = rng.random((h, w, OUT_CHANNELS), dtype=np.float32)
    frame = FeatureFrame(data, Camera(), jitter=jitter)
    frame.motion[...] = motion
    return frame


def test_upscaler_first_frame_repeats_it_as_its_own_still_history():
    config = variant_config("S", 4, 2)
    engine = TorchEngine(perturbed(config))
    upscaler = StatefulUpscaler(engine)
    frame = feature_frame(np.random.default_rng(0), motion=0.3)
    out = upscaler.upscale(frame)
    assert out.shape == (24, 20, 3) and out.min() >= 0 and out.max() <= 1
    from volsr_core.runtime.upscaler import network_inputs

    lr = np.repeat(network_inputs(frame, config.features)[None, None], 3, axis=1)
    jitter = np.tile(np.float32(frame.jitter), (1, 3, 1))
    expected = engine(lr, np.zeros((1, 3, 2, 6, 5), np.float32), jitter)
    assert np.allclose(out, np.clip(expected[0].transpose(1, 2, 0), 0, 1), atol=1e-6)


def test_upscaler_uses_history_and_resets_on_demand_on_size_change_and_on_jumps():
    engine = TorchEngine(perturbed(variant_config("S", 4, 1, recurrent=True)))
    rng = np.random.default_rng(1)
    frames = [feature_frame(rng, jitter=(0.2 * k - 0.3, 0.1)) for k in range(3)]
    upscaler = StatefulUpscaler(engine)
    outs = [upscaler.upscale(f) for f in frames]
    fresh = StatefulUpscaler(engine).upscale(frames[2])
    assert not np.allclose(outs[2], fresh, atol=1e-4), "the third frame must depend on the history"
    assert upscaler.resets == 0
    upscaler.reset()
    assert np.allclose(upscaler.upscale(frames[2]), fresh, atol=1e-6)
    bigger = feature_frame(rng, h=7, w=9)
    assert upscaler.upscale(bigger).shape == (28, 36, 3)
    assert upscaler.last_reset_reason == "size changed" and upscaler.resets == 2
    jump = feature_frame(rng, h=7, w=9, motion=40.0)
    assert np.allclose(upscaler.upscale(jump), StatefulUpscaler(engine).upscale(jump), atol=1e-6)
    assert upscaler.last_reset_reason in ("large motion", "motion leaves the screen")


@pytest.mark.parametrize("shape, step, spread", [((64, 64), 1, 3.0), ((130, 97), 2, 40.0), ((256, 200), 3, 0.0)])
def test_motion_statistics_count_long_and_offscreen_vectors_as_numpy_does(shape, step, spread):
    h, w = shape
    motion = np.random.default_rng(h).normal(0.0, spread, (h, w, 2)).astype(np.float32)
    sample = motion[::step, ::step]
    length = np.sqrt(np.square(sample[..., 0]) + np.square(sample[..., 1]))
    x = np.arange(0, w, step)[None, :] + 0.5 + sample[..., 0]
    y = np.arange(0, h, step)[:, None] + 0.5 + sample[..., 1]
    for limit in (0.5 * spread, float(np.median(length)) * 0.999, float(np.median(length)) * 1.001, 2.0 * spread):
        longer, offscreen = _motion_statistics(sample, step, h, w, limit)
        assert longer == pytest.approx(float(np.mean(length > limit)), abs=1e-3)  # lengths within rounding of it
        lower_median = np.sort(length, axis=None)[length.size - length.size // 2 - 1]
        assert (longer > 0.5) == (lower_median > limit)  # over a half: the median (the lower middle one) is longer
        assert offscreen == pytest.approx(float(np.mean((x < 0) | (x > w) | (y < 0) | (y > h))), abs=1e-12)


def test_pipeline_renders_jittered_lr_frames_and_upscales_them_at_any_size(exported):
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit
    from volsr_core.temporal.jitter import halton_jitter, jitter_phases

    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    model = exported(variant_config("S", 4, 2))  # two previous frames
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), model, scale=4, size=(66, 50))
    assert pipeline.low_resolution_size == (17, 13)
    cameras = orbit(Camera.framing(volume.bounds), 3, degrees=6.0)
    images = [pipeline.render(c) for c in cameras]
    assert all(im.shape == (50, 66, 3) and im.dtype == np.float32 for im in images)
    assert set(pipeline.last_timings) == {"render_ms", "network_ms", "total_ms", "readback_ms"}
    assert pipeline.last_timings["readback_ms"] == 0.0  # made on the host: nothing to copy back
    lr = pipeline.last_low_resolution
    assert lr.jitter == pytest.approx(halton_jitter(2, jitter_phases(4)))
    assert np.abs(lr.motion).max() > 0.1, "frames after the first carry motion vectors"
    assert images[0].std() > 0.01
    pipeline.reset()
    again = pipeline.render(cameras[2])
    assert np.abs(pipeline.last_low_resolution.motion).max() == 0
    assert not np.allclose(again, images[2], atol=1e-3)
    pipeline.render(cameras[0])
    assert pipeline.update(background=(0, 0, 0)) is None, "the same background keeps the history"
    assert pipeline.previous_camera is not None
    assert pipeline.update(background=(0.2, 0.3, 0.4)) == "new background" and pipeline.previous_camera is None
    pipeline.render(cameras[0])
    corner = pipeline.last_low_resolution.color[0, 0]
    assert corner == pytest.approx([0.2, 0.3, 0.4], abs=1e-3), "the new background shows where no ray hits"
    with pytest.raises(ValueError, match="upscales 4x, not 2x"):
        Pipeline(volume, get_preset("CT-Phantom"), model, scale=2)
    assert Pipeline(volume, get_preset("CT-Phantom"), model, size=(66, 50)).scale == 4, "no scale: the model's own"


def test_a_taau_based_upscaler_runs_taau_and_starts_as_it():
    from volsr_core.temporal.taau import TemporalUpsampler

    engine = TorchEngine(SuperResolutionNet(variant_config("S", 4, 0, taau_base=True)))  # zero residual
    upscaler, taau = StatefulUpscaler(engine), TemporalUpsampler(4)
    rng = np.random.default_rng(2)
    for k in range(3):
        frame = feature_frame(rng, jitter=(0.2 * k - 0.3, 0.1), motion=0.0 if k == 0 else 0.4)
        expected = taau(frame.color, np.asarray(frame.motion) * (k > 0), frame.jitter, frame.motion_depth, 0.0)
        assert np.allclose(upscaler.upscale(frame), np.clip(expected, 0, 1), atol=1e-5)


def test_a_network_with_taau_side_outputs_takes_seven_history_channels_and_starts_as_taau(tmp_path):
    from volsr_core.sr.history import HistoryFeed
    from volsr_core.temporal.taau import TemporalUpsampler

    config = variant_config("S", 4, 0, taau_base=True, taau_aux=True)
    assert config.history_channels == 7
    net = SuperResolutionNet(config)  # zero residual: the output is TAAU's
    engine = OnnxEngine(export_onnx(net, tmp_path / "aux.onnx"), providers=["CPUExecutionProvider"])
    upscaler, taau, feed = StatefulUpscaler(engine), TemporalUpsampler(4), HistoryFeed(config)
    rng = np.random.default_rng(3)
    for k in range(3):
        frame = feature_frame(rng, jitter=(0.2 * k - 0.3, 0.1), motion=0.0 if k == 0 else 0.4)
        motion = np.asarray(frame.motion) * (k > 0)
        history = feed(frame.color, motion, frame.jitter, frame.motion_depth, 0.0)
        expected = taau(frame.color, motion, frame.jitter, frame.motion_depth, 0.0)
        assert history.shape == (24, 20, 7) and np.array_equal(history[..., :3], expected)
        np.testing.assert_array_equal(history[..., 3:], taau.last_aux)
        assert np.allclose(upscaler.upscale(frame), np.clip(expected, 0, 1), atol=1e-5)
    with pytest.raises(ValueError, match="taau_aux"):
        variant_config("S", 4, 0, taau_aux=True)


def test_a_u_net_trained_on_the_layered_taau_runs_on_its_depth_slabs_and_starts_as_it(tmp_path):
    """A U-Net with ``taau_slabs`` (its residual zero: the output is its base) renders each frame in its depth slabs
    and refines the layered TAAU's estimate of them, frame by frame, from its ONNX file, as the layered TAAU run
    beside it on the same frames gives (to float rounding); such a network takes no side outputs, and a U-Net not
    trained on slabs is refused them."""
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit
    from volsr_core.temporal.layered import LayeredUpsampler
    from volsr_core.temporal.taau import view_rotation

    config = variant_config("S", 4, 0, taau_base=True, taau_slabs=2)
    onnx = export_onnx(SuperResolutionNet(config), tmp_path / "layered.onnx", example_size=(8, 12))
    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), onnx, scale=4, size=(64, 48))
    assert pipeline.slabs == 2
    layered, previous = LayeredUpsampler(4), None
    for k, camera in enumerate(orbit(Camera.framing(volume.bounds), 4, degrees=3.0)):
        image = pipeline.render(camera)
        lr = pipeline.last_low_resolution
        assert lr.slabs.shape == (2, 12, 16, 6), k
        expected = layered(lr.slabs, lr.jitter, pipeline.caster.background, view_rotation(camera, previous),
                           lr.pixels_per_voxel)
        assert np.abs(image - np.clip(expected, 0, 1)).max() < 1e-5, k
        previous = camera
    assert image.std() > 0.01
    with pytest.raises(ValueError, match="taau_slabs"):
        variant_config("S", 4, 0, taau_base=True, taau_aux=True, taau_slabs=2)
    untrained = TorchEngine(SuperResolutionNet(variant_config("S", 4, 0, taau_base=True)))
    with pytest.raises(ValueError, match="trained on it"):
        StatefulUpscaler(untrained, slabs=2)


def test_pipeline_update_is_the_one_sync_point_idempotent_with_reasons(exported):
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset

    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    model = exported(variant_config("S", 4, 0, taau_base=True))
    tf = get_preset("CT-Phantom")
    pipeline = Pipeline(volume, tf, model, scale=4, size=(32, 32))
    camera = Camera.framing(volume.bounds)
    pipeline.render(camera)
    same = dict(volume=volume, transfer_function=get_preset("CT-Phantom"), background=(0, 0, 0), size=(32, 32))
    assert pipeline.update(**same) is None and pipeline.resets == 0, "equal settings (a new but equal TF) keep it"
    assert pipeline.previous_camera is camera
    other_tf = tf.placed_on(-500.0, 1500.0)
    assert pipeline.update(transfer_function=other_tf, size=(40, 24)) == "new transfer function, new size"
    assert pipeline.resets == 1 and pipeline.previous_camera is None and pipeline.size == (40, 24)
    assert pipeline.update(transfer_function=other_tf, size=(40, 24)) is None, "a second identical call changes nothing"
    copy = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    assert pipeline.update(volume=copy) == "new volume" and pipeline.caster.volume is copy
    assert pipeline.caster.transfer_function is other_tf, "a new volume keeps the transfer function"
    assert pipeline.render(camera).shape == (24, 40, 3)


def test_camera_jump_names_cuts_and_lets_drags_through():
    from volsr_core.runtime.upscaler import camera_jump

    start = Camera(position=[0, -100, 0], focal_point=[0, 0, 0], view_up=[0, 0, 1])
    assert camera_jump(None, start) == ""
    assert camera_jump(start, start.azimuth(5)) == ""
    assert camera_jump(start, start.azimuth(31)) == "camera turned"
    assert camera_jump(start, start.azimuth(31), max_turn=45) == ""
    assert camera_jump(start, start.dolly(2.5)) == "zoom jump" and camera_jump(start, start.dolly(1.5)) == ""
    import dataclasses

    assert camera_jump(start, dataclasses.replace(start, view_angle=20.0)) == "view angle changed"
    assert camera_jump(start, dataclasses.replace(start, parallel_projection=True)) == "projection switched"


def test_the_upscaler_drops_the_history_on_a_camera_jump_in_its_frames():
    engine = TorchEngine(perturbed(variant_config("S", 4, 1, recurrent=True)))
    rng = np.random.default_rng(4)
    start = Camera(position=[0, -100, 0], focal_point=[0, 0, 0], view_up=[0, 0, 1])
    upscaler = StatefulUpscaler(engine, max_turn=30.0)
    first = feature_frame(rng)
    first.camera = start
    upscaler.upscale(first)
    turned = feature_frame(rng, motion=0.2)
    turned.camera, turned.previous_camera = start.azimuth(60), start
    assert np.allclose(upscaler.upscale(turned), StatefulUpscaler(engine).upscale(turned), atol=1e-6)
    assert upscaler.last_reset_reason == "camera turned" and upscaler.resets == 1


def test_a_stretched_pipeline_is_the_model_at_a_smaller_size_then_bicubic():
    """``Pipeline(scale=4, stretch=2)`` renders the 1/4-size frame, runs the 2x model to half the size and stretches
    its image (Keys' cubic, a = -0.75, clamped to [0, 1]): the images of a 2x pipeline at that size stretched by
    ``resize_bicubic``, frame by frame, to float rounding (XS's filter doubles its rows as it makes them), at a size
    the scale does not divide (the LR frame ceil(size / 4), the stretched image cropped as an unstretched one is)."""
    from volsr_core.io import make_phantom
    from volsr_core.runtime.methods import VolSR
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit
    from volsr_core.temporal.jitter import halton_jitter, jitter_phases
    from volsr_core.temporal.resample import resize_bicubic

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    tf = get_preset("CT-Phantom")
    stretched = Pipeline(volume, tf, scale=4, stretch=2, variant="XS", size=(66, 50))
    inner = Pipeline(volume, tf, scale=2, variant="XS", size=(34, 26))
    assert (stretched.scale, stretched.model_scale, stretched.slabs) == (4, 2, 0)  # XS 2x: TAAU, no slabs
    assert stretched.low_resolution_size == inner.low_resolution_size == (17, 13)
    for k, camera in enumerate(orbit(Camera.framing(volume.bounds), 4, degrees=3.0)):
        image = stretched.render(camera)
        expected = resize_bicubic(inner.render(camera), 68, 52, a=-0.75, clamp=(0.0, 1.0))[:50, :66]
        assert image.shape == (50, 66, 3) and np.abs(image - expected).max() < 1e-6, k
        assert stretched.last_low_resolution.jitter == pytest.approx(halton_jitter(k, jitter_phases(2)))
    assert image.std() > 0.01
    assert stretched.last_timings["network_ms"] > 0
    assert VolSR(stretched, "XS").label == "VolSR XS 2x + bicubic 2x" and VolSR(stretched, "XS").scale == 4
    with pytest.raises(ValueError, match="divides the scale and leaves the model at least 2x, got 3 for 4x"):
        Pipeline(volume, tf, scale=4, stretch=3, variant="XS")
    assert Pipeline(volume, tf, stretch=2, variant="XS").scale == 4, "no scale: the shipped default's, stretched"


def test_stretch_auto_picks_by_the_views_pixels_per_voxel_at_each_new_history():
    """``stretch="auto"`` at 4x: XS 4x where a voxel spans fewer than two output pixels, XS 2x stretched 2x where it
    spans more (docs/performance.md, "Where the history lives"), chosen when a history starts; at 2x, or for a given
    model file, there is nothing to choose."""
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import STRETCH_FROM, Pipeline
    from volsr_core.scene import Volume, get_preset

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    tf = get_preset("CT-Phantom")
    pipeline = Pipeline(volume, tf, scale=4, stretch="auto", variant="XS", size=(64, 64))
    wide = Camera.framing(volume.bounds)
    close = wide.zoom(4.0)
    assert pipeline.caster.pixels_per_voxel(wide, 64) < STRETCH_FROM < pipeline.caster.pixels_per_voxel(close, 64)
    assert pipeline.auto_stretch and pipeline.scale == 4
    pipeline.render(wide)
    assert (pipeline.stretch, pipeline.engine.path.name, pipeline.slabs) == (1, "volsr-XS-4x.onnx", 2)
    pipeline.render(close.zoom(1.01))  # the same history, whatever the view: no switch while it lasts
    assert pipeline.stretch == 1
    pipeline.reset()
    image = pipeline.render(close)
    assert (pipeline.stretch, pipeline.engine.path.name, pipeline.slabs) == (2, "volsr-XS-2x.onnx", 0)
    assert image.shape == (64, 64, 3) and pipeline.low_resolution_size == (16, 16)
    assert pipeline.update(size=(32, 32)) == "new size"
    pipeline.render(close)
    assert pipeline.stretch == 1, "a smaller view: the same voxel spans half the pixels"
    assert pipeline.last_reset_reason == "stretch changed"
    assert not Pipeline(volume, tf, scale=2, stretch="auto", variant="XS").auto_stretch
    assert not Pipeline(volume, tf, pipeline.engine.path, scale=4, stretch="auto").auto_stretch  # a file: its own
    # at 8x, where the one 8x model is a U-Net, "auto" runs XS 4x stretched unless a variant is named
    for variant in (None, "XS"):  # XS named at 8x, where it has no model: the same
        eight = Pipeline(volume, tf, scale=8, stretch="auto", variant=variant, size=(64, 64))
        assert (eight.auto_stretch, eight.stretch, eight.engine.path.name) == (False, 2, "volsr-XS-4x.onnx")
    assert Pipeline(volume, tf, scale=8, stretch="auto", variant="S", size=(64, 64)).auto_stretch
    # at 16x, where no model ships, the largest scale below at which the variant ships, stretched
    for variant, stretch, name in ((None, 4, "volsr-XS-4x.onnx"), ("XS", 4, "volsr-XS-4x.onnx"),
                                   ("S", 2, "volsr-S-8x.int8.onnx")):
        sixteen = Pipeline(volume, tf, scale=16, stretch="auto", variant=variant, size=(64, 64))
        assert (sixteen.auto_stretch, sixteen.stretch, sixteen.engine.path.name) == (False, stretch, name)
        assert sixteen.render(wide).shape == (64, 64, 3) and sixteen.low_resolution_size == (4, 4)
    with pytest.raises(ValueError, match="leaves the model at least 2x, got 4 for 4x"):
        Pipeline(volume, tf, scale=4, stretch=4)
    with pytest.raises(ValueError, match="'auto' or a whole number"):
        Pipeline(volume, tf, scale=4, stretch="twice")


def test_xs_on_slabs_takes_one_slab_where_no_pixel_mixes_two_judged_at_each_new_history():
    """Slabs by look (``slabs`` None, XS 4x): two depth slabs where at least MIXED_SHARE of the first frame's shown
    pixels mix two (the phantom's CT-Phantom), one where fewer do (MR-Angio): that frame's slabs composited into one,
    the following ones rendered in one, close to a pipeline told one slab; a new transfer function judges afresh;
    slabs named stay as named; the bench's label says the count is chosen."""
    from volsr_core.io import make_phantom
    from volsr_core.render.slabs import mixed_share
    from volsr_core.runtime.methods import VolSR
    from volsr_core.runtime.pipeline import MIXED_SHARE, Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    unmixed, see_through = get_preset("MR-Angio"), get_preset("CT-Phantom")
    cameras = orbit(Camera.framing(volume.bounds), 5, degrees=2.0)
    by_look = Pipeline(volume, unmixed, scale=4, variant="XS", size=(64, 64))
    told_one = Pipeline(volume, unmixed, scale=4, variant="XS", size=(64, 64), slabs=1)
    told_two = Pipeline(volume, unmixed, scale=4, variant="XS", size=(64, 64), slabs=2)
    assert by_look.slabs_by_look and not told_one.slabs_by_look and not told_two.slabs_by_look
    assert VolSR(by_look, "XS").label == "VolSR XS 4x in 1 or 2 slabs"
    assert VolSR(told_two, "XS").label == "VolSR XS 4x in 2 slabs"
    for k, camera in enumerate(cameras):
        image, reference = by_look.render(camera), told_one.render(camera)
        told_two.render(camera)
        assert by_look.slabs == 1 and by_look.last_frame.slabs.shape == (1, 16, 16, 6), k
        assert told_two.last_frame.slabs.shape[0] == 2 and (told_two.last_frame.slabs[1, ..., 3] > 0.05).any(), k
        if k == 0:
            assert mixed_share(told_two.last_frame.slabs) < MIXED_SHARE
        assert np.abs(image - reference).mean() < 2e-3, k  # the first frame composited, not rendered, in one
    assert image.std() > 0.01 and by_look.resets == 0
    assert by_look.update(transfer_function=see_through) == "new transfer function"
    by_look.render(cameras[0])
    assert by_look.slabs == 2 and mixed_share(by_look.last_frame.slabs) >= MIXED_SHARE
    by_look.render(cameras[1])
    assert by_look.slabs == 2
    assert not Pipeline(volume, unmixed, scale=2, variant="XS").slabs_by_look, "XS 2x runs TAAU: no slabs"


def test_stretch_auto_follows_how_fast_the_view_turns_with_hysteresis():
    """Where the view samples coarsely, ``stretch="auto"`` runs XS 4x while the view turns slowly and XS 2x stretched
    once the median of the last three frames' turns times the view's pixels per voxel reaches 3.5, back below 2.5: in
    between it keeps what it runs, and each change starts the other model's history afresh (docs/performance.md,
    "How fast the view turns")."""
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import FAST_TURN, STRETCH_FROM, TURN_FRAMES, Pipeline
    from volsr_core.scene import Volume, get_preset

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), scale=4, stretch="auto", variant="XS", size=(64, 64))
    camera = Camera.framing(volume.bounds)
    per_voxel = pipeline.caster.pixels_per_voxel(camera, 64)  # the same while the camera orbits its focal point
    assert per_voxel < STRETCH_FROM and FAST_TURN == (2.5, 3.5) and TURN_FRAMES == 3
    moves = [0, 1, 1, 6, 6, 6, 3, 3, 3, 1, 1, 5]  # degrees a frame times pixels per voxel (the first: new)
    stretches, reasons = [], []
    for move in moves:
        camera = camera.azimuth(move / per_voxel)
        image = pipeline.render(camera)
        stretches.append(pipeline.stretch)
        reasons.append(pipeline.last_reset_reason)
        assert image.shape == (64, 64, 3) and pipeline.low_resolution_size == (16, 16)
    # from the second frame on, medians of the last three: 1, 1, 1, 6, 6, 6, 3, 3, 3, 1, 1
    assert stretches == [1, 1, 1, 1, 2, 2, 2, 2, 2, 2, 1, 1]
    assert reasons[4] == "stretch changed" and pipeline.slabs == 2
    pipeline.reset()
    pipeline.render(camera.azimuth(6.0 / per_voxel))
    assert pipeline.stretch == 1, "a new history starts with no turns measured"
