"""The comparison methods (runtime/methods.py) and the history policy (sr/history.py): one home each,
checked against the pieces they are made of."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.runtime.methods import Native, ReducedSize, Taau
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.scene.camera_paths import orbit_around
from volsr_core.sr.history import HistoryFeed, pick_history, taau_upsampler
from volsr_core.sr.network_config import variant_config
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.temporal.layered import LayeredUpsampler
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.resample import resize_bilinear, upscale_bicubic
from volsr_core.temporal.taau import TemporalUpsampler, view_rotation

SIZE = (48, 40)


@pytest.fixture(scope="module")
def caster():
    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    return RayCaster(volume, get_preset("CT-Phantom"))


def test_native_is_the_supersampled_render(caster):
    camera = Camera.framing(caster.volume.bounds, aspect=SIZE[0] / SIZE[1])
    for spp in (1, 4):
        frame = Native(caster, SIZE, spp)(camera)
        assert np.array_equal(frame.image, render_supersampled(caster, camera, *SIZE, spp=spp))
        assert frame.ms_upscale == 0 and frame.ms_total == frame.ms_render > 0
    assert Native(caster, SIZE, 4).label == "native 4 spp"


def test_reduced_size_renders_pixel_centres_and_stretches_them_over_the_view(caster):
    camera = Camera.framing(caster.volume.bounds, aspect=SIZE[0] / SIZE[1])
    method = ReducedSize(caster, SIZE, 3)
    frame = method(camera)
    w, h = method.low_resolution_size
    assert (w, h) == (16, 13)
    lr = caster.render(camera, w, h).color  # pixel centres, no jitter: what VTK's ImageSampleDistance renders
    assert frame.low_resolution is None, "the colour alone (no feature buffers), as VTK's renderer makes it"
    assert np.array_equal(frame.image, resize_bilinear(lr, *SIZE)) and frame.image.shape == (40, 48, 3)
    bicubic = ReducedSize(None, (32, 24), 4, "bicubic")
    small = np.random.default_rng(0).random((6, 8, 3), dtype=np.float32)
    assert np.allclose(bicubic.upscale(small), np.clip(upscale_bicubic(small, 4), 0, 1))
    assert method.label == "native 1/3 size + bilinear" and bicubic.kind == "bicubic"
    fractional = ReducedSize(caster, SIZE, 2.5)  # VTK's ImageSampleDistance need not be whole either
    assert fractional.low_resolution_size == (19, 16) and fractional.label == "native 1/2.5 size + bilinear"
    lr = caster.render(camera, 19, 16).color
    assert np.array_equal(fractional(camera).image, resize_bilinear(lr, *SIZE))
    with pytest.raises(ValueError, match="interpolation"):
        ReducedSize(None, SIZE, 2, "nearest")


def test_taau_method_is_halton_jittered_frames_through_the_networks_taau(caster):
    cameras = orbit_around(caster.volume.bounds, 4, 2.0, aspect=SIZE[0] / SIZE[1])
    method, upsampler = Taau(caster, SIZE, 2), taau_upsampler(2)
    previous = None
    for t, camera in enumerate(cameras):
        frame = method(camera)
        lr = caster.render(camera, 24, 20, jitter=halton_jitter(t, jitter_phases(2)), previous_camera=previous)
        assert frame.low_resolution.jitter == lr.jitter
        expected = upsampler(lr.color, lr.motion, lr.jitter, lr.motion_depth, view_rotation(camera, previous))
        assert np.array_equal(frame.image, expected)
        previous = camera
    method.reset()
    assert method.previous is None and method.upsampler.history is None


def test_a_layered_taau_method_upscales_the_frames_depth_slabs(caster):
    cameras = orbit_around(caster.volume.bounds, 3, 2.0, aspect=SIZE[0] / SIZE[1])
    method, upsampler = Taau(caster, SIZE, 2, slabs=3), LayeredUpsampler(2)
    assert method.label == "TAAU 2x in 3 slabs" and method.kind == "taau"
    previous = None
    for t, camera in enumerate(cameras):
        frame = method(camera)
        lr = caster.render(camera, 24, 20, jitter=halton_jitter(t, jitter_phases(2)), previous_camera=previous,
                           slabs=3, seed=t)
        expected = upsampler(lr.slabs, lr.jitter, caster.background, view_rotation(camera, previous),
                             lr.pixels_per_voxel)
        assert np.array_equal(frame.image, expected) and frame.image.shape == (40, 48, 3)
        previous = camera
    with pytest.raises(ValueError, match="slabs"):
        method.upscale(frame.low_resolution.color, frame.low_resolution.motion, (0.0, 0.0))


def test_pick_history_and_the_feed_follow_the_networks_configuration():
    assert pick_history("none", "out", "taau") is None
    assert pick_history("recurrent", "out", "taau") == "out"
    assert pick_history("taau", "out", "taau") == "taau"
    with pytest.raises(ValueError, match="history mode"):
        pick_history("both", None, None)
    rng = np.random.default_rng(3)
    colour, motion = rng.random((5, 6, 3), dtype=np.float32), np.zeros((5, 6, 2), np.float32)
    taau_feed, reference = HistoryFeed(variant_config("S", 2, 0, taau_base=True)), TemporalUpsampler(2)
    for jitter in ((0.1, -0.2), (-0.3, 0.25)):
        assert np.array_equal(taau_feed(colour, motion, jitter), reference(colour, motion, jitter))
    recurrent = HistoryFeed(variant_config("S", 2, 1, recurrent=True))
    assert recurrent(colour, motion, (0.0, 0.0)) is None, "a recurrent network's first frame has no history"
    output = rng.random((10, 12, 3), dtype=np.float32)
    recurrent.keep(output)
    assert recurrent(colour, motion, (0.0, 0.0)) is output
    recurrent.reset()
    assert recurrent(colour, motion, (0.0, 0.0)) is None
    plain = HistoryFeed(variant_config("S", 2, 2))
    plain.keep(output)
    assert plain.mode == "none" and plain(colour, motion, (0.0, 0.0)) is None


def test_only_a_fine_sampling_network_tells_its_taau_the_pixels_per_voxel():
    """A fine frame (3 output pixels per voxel) while the view rotates: TAAU smooths it when told, so the feed
    of a ``taau_fine_sampling`` network matches TAAU told, and an older network's matches TAAU not told."""
    rng = np.random.default_rng(4)
    frames = [(rng.random((6, 7, 3), dtype=np.float32), rng.normal(0, 0.3, (6, 7, 2)).astype(np.float32), jitter)
              for jitter in ((0.1, -0.2), (-0.3, 0.25), (0.2, 0.1))]
    told = HistoryFeed(variant_config("XS", 2, taau_base=True, taau_fine_sampling=True))
    untold = HistoryFeed(variant_config("XS", 2, taau_base=True))
    smoothing, plain = TemporalUpsampler(2), TemporalUpsampler(2)
    for colour, motion, jitter in frames:
        fine = told(colour, motion, jitter, None, 2.0, 1.5)
        coarse = untold(colour, motion, jitter, None, 2.0, 1.5)
        assert np.array_equal(fine, smoothing(colour, motion, jitter, None, 2.0, 1.5))
        assert np.array_equal(coarse, plain(colour, motion, jitter, None, 2.0))
        assert not np.allclose(fine, coarse)
    with pytest.raises(ValueError, match="taau_fine_sampling"):
        variant_config("S", 2, taau_fine_sampling=True)
