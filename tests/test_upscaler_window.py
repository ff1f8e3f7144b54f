"""The U-Nets on the volume's window alone: where the window lies, and that the image is the whole frame's."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.runtime.content_window import NEARBY, WINDOW_ALIGN, WINDOW_MARGIN, content_window, shows_nearby


def test_the_window_holds_what_the_frame_or_the_base_shows_widened_and_aligned():
    """Alpha shows LR rows 20-23 and columns 30-40; the base (2x) differs from the background at HR (100, 9), LR
    (50, 4), and nowhere else; the window is their hull widened by the margin, its corners moved out to multiples of
    the alignment and clipped to the 64 x 72 frame."""
    background = (0.2, 0.3, 0.4)
    alpha = np.zeros((64, 72), np.float32)
    alpha[20:24, 30:41] = 0.5
    base = np.empty((3, 128, 144), np.float32)
    base[:] = np.float32(background)[:, None, None]
    assert content_window(alpha, base, background, 2) == (12, 32, 20, 52)  # rows 20 - 8 .. 24 + 8, columns 22 .. 49
    base[:, 100, 9] = (0.2, 0.3, 0.41)
    top, bottom, left, right = content_window(alpha, base, background, 2)
    assert (top, left) == ((20 - WINDOW_MARGIN) // WINDOW_ALIGN * WINDOW_ALIGN, 0)  # LR column 4 - 8 clipped to 0
    assert (bottom, right) == (-(-(50 + 1 + WINDOW_MARGIN) // WINDOW_ALIGN) * WINDOW_ALIGN, 52)
    base[:, 100, 9] = background
    alpha[:] = 0.0
    assert content_window(alpha, base, background, 2) == (0, 0, 0, 0)
    alpha[63, 71] = 1e-6
    assert content_window(alpha, base, background, 2, margin=0, align=1) == (63, 64, 71, 72)
    base[:, 0, 0] = 1.0  # not read: a base given as None is the background beyond one LR pixel of the alpha
    assert content_window(alpha, None, background, 2, margin=0, align=1) == (62, 64, 70, 72)


def test_shows_nearby_marks_the_window_pixels_within_reach_of_what_shows():
    """Alpha shows at LR (10, 10) and (3, 30) alone: in the window rows 5-19, columns 5-34 the pixels within two
    (Chebyshev distance) of either are marked, those of a pixel outside the window included, and no other."""
    alpha = np.zeros((24, 40), np.float32)
    alpha[10, 10] = 0.3
    alpha[3, 30] = 1e-6
    marked = shows_nearby(alpha, (5, 20, 5, 35))
    rows, columns = np.mgrid[5:20, 5:35]
    near = lambda y, x: np.maximum(abs(rows - y), abs(columns - x)) <= NEARBY  # noqa: E731
    assert marked.shape == (15, 30) and np.array_equal(marked, near(10, 10) | near(3, 30))
    assert NEARBY == 2 and marked.sum() == 25 + 5 and not shows_nearby(alpha * 0, (5, 20, 5, 35)).any()


class CountingEngine:
    """A real engine whose calls are counted, whose inputs' LR sizes are kept, and its last inputs and output."""

    def __init__(self, engine):
        self.engine, self.config, self.sizes = engine, engine.config, []

    def __call__(self, lr, motion, jitter, history=None):
        self.sizes.append(lr.shape[-2:])
        self.last = [np.array(value) for value in (lr, motion, jitter, history)]
        self.output = self.engine(lr, motion, jitter, history)
        return self.output


def test_the_shipped_u_net_on_the_volumes_window_gives_the_whole_frames_image_where_the_volume_shows(model):
    """The shipped S 4x on a phantom in the middle of a 256² view over a coloured background: run on the window (the
    default) it sees a part of each LR frame; where the volume shows its images lie within 5e-3 of those it makes on
    the whole frame (PSNR there above 60 dB), outside the window they are the background exactly (the network run on
    every pixel tints a background it was not trained on by up to about 0.02), and a view that shows nothing runs no
    network and is the background."""
    pytest.importorskip("onnxruntime")
    from volsr_core.io import make_phantom
    from volsr_core.runtime.engines import OnnxEngine
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera import Camera
    from volsr_core.scene.camera_paths import orbit

    background = np.float32([0.1, 0.1, 0.2])
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    pipelines = [Pipeline(volume, get_preset("CT-Phantom"), model, scale=4, size=(256, 256), threads=2,
                          background=tuple(background)) for _ in range(2)]
    engines = [CountingEngine(OnnxEngine(model, providers=["CPUExecutionProvider"])) for _ in range(2)]
    for pipeline, engine in zip(pipelines, engines):
        pipeline.upscaler.engine = engine
    pipelines[1].upscaler.skip_background = False
    start = Camera.framing(volume.bounds).dolly(0.45).reset_clipping_range(volume.bounds)
    for camera in orbit(start, 5, degrees=10.0):
        window, whole = (pipeline.render(camera) for pipeline in pipelines)
        shows = np.repeat(np.repeat(pipelines[0].last_low_resolution.alpha > 0, 4, 0), 4, 1)
        top, bottom, left, right = pipelines[0].upscaler.last_window
        inside = np.zeros(shows.shape, bool)
        inside[4 * top:4 * bottom, 4 * left:4 * right] = True
        assert shows.mean() > 0.01 and not (shows & ~inside).any()
        error = float(np.mean((window[shows] - whole[shows]) ** 2))
        assert np.abs(window[shows] - whole[shows]).max() < 5e-3 and 10 * np.log10(1.0 / error) > 60.0
        np.testing.assert_array_equal(window[~inside], np.broadcast_to(background, window[~inside].shape))
        assert engines[0].sizes[-1] == (bottom - top, right - left) and engines[1].sizes[-1] == (64, 64)
        assert (bottom - top) * (right - left) < 0.6 * 64 * 64
    away = Camera(position=start.position, focal_point=2 * start.position - start.focal_point, view_up=start.view_up)
    calls = len(engines[0].sizes)
    image = pipelines[0].render(away)
    assert len(engines[0].sizes) == calls and pipelines[0].upscaler.last_window == (0, 0, 0, 0)
    np.testing.assert_array_equal(image, np.broadcast_to(background, image.shape))


def test_the_shipped_u_net_leaves_a_light_background_as_it_is_where_nothing_shows_nearby(model):
    """The shipped S 4x on the phantom over a light background (3D Slicer's, about): where the LR frame shows nothing
    within :data:`NEARBY` LR pixels its images are the background exactly, inside the window too, where the network
    alone, run there, tints it by more than 0.01; where the volume shows they are the network's own."""
    pytest.importorskip("onnxruntime")
    from volsr_core.io import make_phantom
    from volsr_core.runtime.engines import OnnxEngine
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera import Camera
    from volsr_core.scene.camera_paths import orbit

    background = np.float32([0.76, 0.76, 0.87])
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), model, scale=4, size=(256, 256), threads=2,
                        background=tuple(background))
    engine = pipeline.upscaler.engine = CountingEngine(OnnxEngine(model, providers=["CPUExecutionProvider"]))
    start = Camera.framing(volume.bounds).dolly(0.45).reset_clipping_range(volume.bounds)
    tints = []
    for camera in orbit(start, 4, degrees=4.0):
        image = pipeline.render(camera)
        top, bottom, left, right = pipeline.upscaler.last_window
        window = image[4 * top:4 * bottom, 4 * left:4 * right]
        network = np.clip(engine.output[0].transpose(1, 2, 0), 0.0, 1.0)
        near = np.repeat(np.repeat(shows_nearby(pipeline.last_low_resolution.alpha, (top, bottom, left, right)), 4, 0),
                         4, 1)
        assert 0.05 < near.mean() < 0.95
        np.testing.assert_array_equal(window[~near], np.broadcast_to(background, window[~near].shape))
        np.testing.assert_array_equal(window[near], network[near])
        tints.append(float(np.abs(network[~near] - background).max()))
    assert max(tints) > 0.01


def test_the_window_network_inputs_are_the_whole_frames_cut_to_it(model):
    """On each frame of an orbit the shipped S 4x is given the window of what it took on the whole frame: the frame's
    features stacked (``network_inputs``), its motion vectors (zeros on the first frame) and jitter, and the TAAU
    estimate's pixels; where the frame shows something near the image is the network's output clipped to [0, 1]."""
    pytest.importorskip("onnxruntime")
    from volsr_core.io import make_phantom
    from volsr_core.runtime.engines import OnnxEngine
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.runtime.upscaler import network_inputs
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera import Camera
    from volsr_core.scene.camera_paths import orbit

    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    pipeline = Pipeline(volume, get_preset("CT-Phantom"), model, scale=4, size=(256, 256), threads=2)
    engine = pipeline.upscaler.engine = CountingEngine(OnnxEngine(model, providers=["CPUExecutionProvider"]))
    start = Camera.framing(volume.bounds).dolly(0.45).reset_clipping_range(volume.bounds)
    for index, camera in enumerate(orbit(start, 3, degrees=4.0)):
        image = pipeline.render(camera)
        frame = pipeline.last_low_resolution
        top, bottom, left, right = pipeline.upscaler.last_window
        assert 0 < (bottom - top) * (right - left) < 0.8 * 64 * 64
        lr, motion, jitter, history = engine.last
        rows, columns = slice(top, bottom), slice(left, right)
        np.testing.assert_array_equal(lr[0, 0], network_inputs(frame, engine.config.features)[:, rows, columns])
        vectors = frame.motion[rows, columns].transpose(2, 0, 1) if index else np.zeros_like(motion[0, 0])
        np.testing.assert_array_equal(motion[0, 0], vectors)
        np.testing.assert_array_equal(jitter, np.float32(frame.jitter)[None, None])
        assert history.shape == (1, 3, 4 * (bottom - top), 4 * (right - left))
        window = image[4 * top:4 * bottom, 4 * left:4 * right]
        near = np.repeat(np.repeat(shows_nearby(frame.alpha, (top, bottom, left, right)), 4, 0), 4, 1)
        np.testing.assert_array_equal(window[near], np.clip(engine.output[0].transpose(1, 2, 0), 0.0, 1.0)[near])
