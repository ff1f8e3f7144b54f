"""Temporal upsampling: where samples land, accumulation weights, a CT_AVM orbit, upscaling baselines."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.temporal import (
    TemporalUpsampler, halton_jitter, jitter_phases, render_supersampled, upscale_bicubic, upscale_bilinear,
)
from volsr_core.temporal.taau import sample_offset


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2)))


def test_ct_avm_orbit_at_4x_beats_single_frame_upscaling(ct_avm_path):
    """LR 48² frames of a 0.75 degree/frame orbit, Halton jitter, renderer motion vectors; HR 192²."""
    volume = Volume.load(ct_avm_path)
    caster = RayCaster(volume, get_preset("CT-AAA").placed_on(0.0, 446.0))
    start = Camera.framing(volume.bounds, direction=(0.4, 1.0, -0.3)).zoom(1.5)
    cameras = [start.azimuth(0.75 * i).reset_clipping_range(volume.bounds) for i in range(32)]
    scale, lr_size = 4, 48
    taau = TemporalUpsampler(scale)
    scores = []
    for i, camera in enumerate(cameras):
        jitter = halton_jitter(i, jitter_phases(scale))
        frame = caster.render(camera, lr_size, jitter=jitter, previous_camera=cameras[i - 1] if i else None, seed=i)
        output = taau(frame.color, frame.motion, jitter)
        if i < len(cameras) - 3:
            continue
        truth = render_supersampled(caster, camera, lr_size * scale, spp=16)
        centred = caster.render(camera, lr_size).color  # what an interactive low-resolution view shows
        scores.append({"taau": psnr(output, truth), "bilinear": psnr(upscale_bilinear(centred, scale), truth),
                       "bicubic": psnr(upscale_bicubic(centred, scale), truth),
                       "bilinear of the jittered frame": psnr(upscale_bilinear(frame.color, scale), truth)})
    for i, s in enumerate(scores):
        print(f"CT_AVM 4x orbit, frame {len(cameras) - 3 + i}: PSNR vs 16 spp: "
              + ", ".join(f"{k} {v:.2f} dB" for k, v in s.items()))
    for s in scores:
        assert s["taau"] >= max(s["bilinear"], s["bicubic"], s["bilinear of the jittered frame"]) + 0.5


@pytest.mark.parametrize("scale, jitter", [(4, (0.3, -0.2)), (3, (-0.45, 0.1)), (2, (0.0, 0.49))])
def test_samples_land_on_the_hr_pixels_they_were_taken_at(scale, jitter):
    """Fresh history: each LR value sits exactly on the HR pixel containing its sample position."""
    lr = np.random.default_rng(5).random((6, 7, 3), dtype=np.float32)
    hr = TemporalUpsampler(scale)(lr, np.zeros((6, 7, 2), dtype=np.float32), jitter)
    assert hr.shape == (6 * scale, 7 * scale, 3)
    ys, xs = np.mgrid[0:6, 0:7]
    hr_x = np.floor((xs + 0.5 + jitter[0]) * scale).astype(int)  # LR position -> HR position -> pixel
    hr_y = np.floor((ys + 0.5 + jitter[1]) * scale).astype(int)
    np.testing.assert_array_equal(hr[hr_y, hr_x], lr)
    landed = np.zeros(hr.shape[:2], dtype=bool)
    landed[hr_y, hr_x] = True
    assert landed.sum() == lr.shape[0] * lr.shape[1]


def test_pixels_without_a_sample_interpolate_between_the_jittered_sample_positions():
    """A linear ramp sampled at jittered positions is rebuilt on the HR pixel centres (interior)."""
    scale, (jx, jy) = 4, (0.3, -0.2)

    def ramp(x: np.ndarray, y: np.ndarray) -> np.ndarray:  # x, y in LR continuous coordinates
        return np.stack([0.1 + 0.05 * x, 0.2 + 0.03 * y, 0.3 + 0.02 * x - 0.01 * y], axis=-1).astype(np.float32)

    ys, xs = np.mgrid[0:8, 0:8].astype(np.float64)
    hr = TemporalUpsampler(scale)(ramp(xs + 0.5 + jx, ys + 0.5 + jy), np.zeros((8, 8, 2), dtype=np.float32),
                                  (jx, jy))
    hys, hxs = (np.mgrid[0:32, 0:32] + 0.5) / scale
    between = np.zeros((32, 32), dtype=bool)
    between[4:28, 4:28] = True  # HR centres between the outermost samples
    between[np.floor((ys + 0.5 + jy) * scale).astype(int), np.floor((xs + 0.5 + jx) * scale).astype(int)] = False
    np.testing.assert_allclose(hr[between], ramp(hxs, hys)[between], atol=1e-5)


def test_a_still_pixel_averages_its_samples_until_the_cap_then_blends_by_one_minus_w():
    """Grey stripes 0.2 / 0.5 / 0.8 keep each 0.5 pixel's history inside its box, so nothing is clamped.

    The jitter puts every sample on its HR pixel's centre (weight 1). With history_weight 0.75
    the count is capped at 3: samples 1..4 are averaged, later ones get 1 - 0.75 = 1/4.
    """
    scale = 4
    jitter = (0.125, 0.125)  # (i + 0.5 + 0.125) * 4 = 4 i + 2.5: the centre of HR pixel 4 i + 2
    stripes = np.tile(np.array([0.2, 0.5, 0.8], dtype=np.float32), 3)[None, :, None] * np.ones((9, 9, 3), np.float32)
    offsets = np.array([0.03, -0.02, 0.01, 0.04, -0.05, 0.0, 0.02], dtype=np.float32)
    taau = TemporalUpsampler(scale, history_weight=0.75)
    expected = 0.5 + offsets[0]
    for k, offset in enumerate(offsets):
        hr = taau(stripes + offset, np.zeros((9, 9, 2), dtype=np.float32), jitter)
        value = 0.5 + offset
        expected = value if k == 0 else expected + (value - expected) / min(k + 1, 4)
        np.testing.assert_allclose(hr[4 * 4 + 2, 4 * 1 + 2], expected, atol=1e-6)


def test_reset_and_size_change_start_again_from_the_current_frame():
    rng = np.random.default_rng(6)
    still = np.zeros((5, 5, 2), dtype=np.float32)
    taau = TemporalUpsampler(2)
    first = taau(rng.random((5, 5, 3), dtype=np.float32), still, (0.0, 0.0))
    second = rng.random((5, 5, 3), dtype=np.float32)
    taau.reset()
    np.testing.assert_array_equal(taau(second, still, (0.0, 0.0)), TemporalUpsampler(2)(second, still, (0.0, 0.0)))
    assert first.shape == (10, 10, 3)
    other = rng.random((3, 4, 3), dtype=np.float32)
    fresh = TemporalUpsampler(2)(other, np.zeros((3, 4, 2), dtype=np.float32), (0.0, 0.0))
    np.testing.assert_array_equal(taau(other, np.zeros((3, 4, 2), dtype=np.float32), (0.0, 0.0)), fresh)


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="scale"):
        TemporalUpsampler(0)
    with pytest.raises(ValueError, match="jitter"):
        TemporalUpsampler(2)(np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 2), np.float32), (0.5, 0.0))
    with pytest.raises(ValueError, match="sample_sigma"):
        TemporalUpsampler(2, sample_sigma=0.0)


def test_jitter_phases_follow_fsr2():
    assert [jitter_phases(s) for s in (1, 2, 3, 4)] == [8, 32, 72, 128]


@pytest.mark.parametrize("upscale", [upscale_bilinear, upscale_bicubic])
@pytest.mark.parametrize("scale", [2, 3, 4])
def test_upscaling_keeps_constants_and_linear_ramps(upscale, scale):
    """Pixel-centre convention: HR pixel X samples LR continuous coordinate (X + 0.5) / scale."""
    h, w = 7, 9
    constant = np.full((h, w, 3), 0.37, dtype=np.float32)
    np.testing.assert_allclose(upscale(constant, scale), constant[0, 0, 0], atol=1e-6)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    lr = (0.1 + 0.06 * xs - 0.04 * ys).astype(np.float32)
    hr = upscale(lr, scale)
    assert hr.shape == (h * scale, w * scale) and hr.dtype == np.float32
    hys, hxs = (np.mgrid[0:h * scale, 0:w * scale] + 0.5) / scale
    margin = 1.5 if upscale is upscale_bicubic else 0.5  # LR pixels whose taps reach past the edge
    inside = ((hxs >= margin) & (hxs <= w - margin)) & ((hys >= margin) & (hys <= h - margin))
    np.testing.assert_allclose(hr[inside], (0.1 + 0.06 * hxs - 0.04 * hys)[inside], atol=1e-5)


@pytest.mark.parametrize("scale", [2, 3, 4])
def test_upscaling_matches_torch_interpolate(scale):
    torch = pytest.importorskip("torch")
    lr = np.random.default_rng(7).random((11, 13, 3), dtype=np.float32)
    nchw = torch.from_numpy(lr).permute(2, 0, 1)[None]
    for mode, ours in (("bilinear", upscale_bilinear(lr, scale)), ("bicubic", upscale_bicubic(lr, scale, a=-0.75))):
        theirs = torch.nn.functional.interpolate(nchw, scale_factor=scale, mode=mode, align_corners=False)
        np.testing.assert_allclose(ours, theirs[0].permute(1, 2, 0).numpy(), atol=1e-5)


@pytest.mark.parametrize("scale", [2, 3, 4])
def test_one_halton_cycle_puts_samples_on_every_hr_pixel(scale):
    hits = {(sample_offset(jx, scale), sample_offset(jy, scale))
            for jx, jy in (halton_jitter(i, jitter_phases(scale)) for i in range(jitter_phases(scale)))}
    assert hits == {(x, y) for x in range(scale) for y in range(scale)}
