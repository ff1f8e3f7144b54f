"""Temporal anti-aliasing: convergence on a still camera, no ghosting after disocclusion, resets."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.temporal import TemporalAntiAliasing, backward_warp, halton_jitter, render_supersampled

VARIANTS = [
    {},
    {"clamp": "variance"},
    {"reprojection": "catmull_rom"},
    {"rectify": "clip"},
]


def grow(mask: np.ndarray) -> np.ndarray:
    """``mask`` dilated by one pixel (3x3)."""
    padded = np.pad(mask, 1)
    h, w = mask.shape
    return np.any([padded[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)], axis=0)


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2)))


def scene(name: str, request) -> tuple[RayCaster, Camera]:
    if name == "phantom":
        volume, tf = Volume.from_record(make_phantom()), get_preset("CT-Phantom")
        direction, zoom = (0.3, 1.0, -0.2), 1.6
    else:
        volume = Volume.load(request.getfixturevalue("ct_avm_path"))
        tf, direction, zoom = get_preset("CT-AAA").placed_on(0.0, 446.0), (0.4, 1.0, -0.3), 1.5
    camera = Camera.framing(volume.bounds, direction=direction).zoom(zoom).reset_clipping_range(volume.bounds)
    return RayCaster(volume, tf), camera


@pytest.mark.parametrize("name", ["phantom", "CT_AVM"])
def test_still_camera_converges_to_the_supersampled_image(name, request):
    caster, camera = scene(name, request)
    size = 160
    reference = render_supersampled(caster, camera, size, spp=16)
    taa = TemporalAntiAliasing()
    for i in range(32):
        frame = caster.render(camera, size, jitter=halton_jitter(i, 16), previous_camera=camera, seed=i)
        output = taa(frame.color, frame.motion)
    single, accumulated = psnr(frame.color, reference), psnr(output, reference)
    print(f"{name} {size}²: PSNR vs 16 spp, TAA after 32 frames {accumulated:.2f} dB, "
          f"one jittered frame {single:.2f} dB")
    assert accumulated >= 35.0
    assert accumulated >= single + 10.0


def textured_background(h: int, w: int) -> np.ndarray:
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    v = 0.25 + 0.1 * np.sin(xs * 0.7) * np.cos(ys * 0.5)
    return np.stack([v, 0.9 * v, 0.8 * v], axis=-1)


def occluded_frame(t: int, size: int = 64, side: int = 16, speed: int = 2):
    """Truth, occluder mask and exact motion at frame ``t``: a bright textured square moving right."""
    image = textured_background(size, size)
    ys, xs = np.mgrid[0:size, 0:size].astype(np.float32)
    x0, y0 = 4 + speed * t, 24
    mask = np.zeros((size, size), dtype=bool)
    mask[y0:y0 + side, x0:x0 + side] = True
    v = 0.85 + 0.1 * np.sin((xs - x0) * 1.3) * np.cos(ys * 0.9)
    image[mask] = np.stack([v, 0.95 * v, 0.7 * v], axis=-1)[mask]
    motion = np.zeros((size, size, 2), dtype=np.float32)
    motion[mask, 0] = -speed  # the occluder's points were `speed` pixels further left
    return image, mask, motion


@pytest.mark.parametrize("options", VARIANTS, ids=lambda o: "-".join(o.values()) or "default")
def test_uncovered_background_follows_the_current_frame(options):
    """Behind a moving occluder the clamp rejects the stale history; plain blending ghosts.

    Frames are the truth plus noise (sigma 0.03). Scored over the background the occluder
    uncovered in the last 6 frames, minus the 1-pixel ring around the occluder where the 3x3
    box necessarily holds occluder colours.
    """
    rng = np.random.default_rng(1)
    taa = TemporalAntiAliasing(**options)
    plain = None
    masks, errors = [], {"taa": [], "plain": [], "current": [], "taa still": [], "current still": []}
    for t in range(20):
        truth, mask, motion = occluded_frame(t)
        current = (truth + rng.normal(0.0, 0.03, truth.shape)).astype(np.float32)
        output = taa(current, motion)
        plain = current if plain is None else 0.9 * backward_warp(plain, motion)[0] + 0.1 * current
        masks.append(mask)
        if t < 8:
            continue
        uncovered = np.any(masks[-7:-1], axis=0) & ~grow(mask)
        still = np.ones_like(mask)
        still[16:48] = False
        for key, image in (("taa", output), ("plain", plain), ("current", current)):
            errors[key].append(np.abs(image - truth)[uncovered].mean())
        errors["taa still"].append(np.abs(output - truth)[still].mean())
        errors["current still"].append(np.abs(current - truth)[still].mean())
    e = {key: float(np.mean(values)) for key, values in errors.items()}
    print(f"{options or 'default'}: mean |error| uncovered: TAA {e['taa']:.4f}, no history {e['current']:.4f}, "
          f"plain blending {e['plain']:.4f}; still background: TAA {e['taa still']:.4f}, "
          f"no history {e['current still']:.4f}")
    assert e["taa"] <= 1.5 * e["current"]
    assert e["plain"] >= 5.0 * e["taa"]
    assert e["taa still"] <= 0.5 * e["current still"]


def test_reprojection_off_screen_restarts_from_the_current_frame():
    rng = np.random.default_rng(2)
    first, second = rng.random((32, 32, 3), dtype=np.float32), rng.random((32, 32, 3), dtype=np.float32)
    motion = np.zeros((32, 32, 2), dtype=np.float32)
    motion[:, 16:, 0] = 40.0  # the right half was beyond the right edge
    motion[:8, :16, 1] = -12.0  # the top-left corner above the top edge
    taa = TemporalAntiAliasing()
    taa(first, motion)
    output = taa(second, motion)
    off = np.zeros((32, 32), dtype=bool)
    off[:, 16:] = off[:8, :16] = True
    np.testing.assert_array_equal(output[off], second[off])
    assert np.abs(output[~off] - second[~off]).max() > 0.01, "on-screen pixels keep some history"


@pytest.mark.parametrize("options", [o for o in VARIANTS if o.get("clamp") != "variance"],
                         ids=lambda o: "-".join(o.values()) or "default")
def test_identical_frames_without_motion_are_a_fixed_point(options):
    """The min/max box holds each pixel's own colour. (A variance box need not: it pulls outliers.)"""
    image = np.random.default_rng(3).random((24, 40, 3), dtype=np.float32)
    taa = TemporalAntiAliasing(**options)
    for _ in range(5):
        output = taa(image, np.zeros((24, 40, 2), dtype=np.float32))
    np.testing.assert_allclose(output, image, atol=1e-6)


def test_catmull_rom_keeps_a_translating_texture_sharper_than_bilinear():
    """Half-pixel steps are bilinear's worst case: it blurs the history every frame."""
    ys, xs = np.mgrid[0:64, 0:64].astype(np.float32)
    motion = np.zeros((64, 64, 2), dtype=np.float32)
    motion[..., 0] = -0.5
    errors = {}
    for reprojection in ("bilinear", "catmull_rom"):
        taa = TemporalAntiAliasing(reprojection=reprojection)
        for t in range(24):
            u = xs + 0.5 - 0.5 * t
            v = 0.5 + 0.2 * np.sin(u * 0.9) * np.cos(ys * 0.7) + 0.15 * np.sin(u * 0.37 + ys * 0.45)
            truth = np.stack([v, 0.8 * v, 0.6 * v], axis=-1)
            output = taa(truth, motion)
        errors[reprojection] = float(np.abs(output - truth)[4:-4, 16:-4].mean())
    print(f"translating texture, mean |error|: {errors}")
    assert errors["catmull_rom"] < 0.5 * errors["bilinear"]


def test_first_frame_reset_and_size_change_return_the_current_frame():
    rng = np.random.default_rng(4)
    a, b = rng.random((16, 16, 3), dtype=np.float32), rng.random((16, 16, 3), dtype=np.float32)
    still = np.zeros((16, 16, 2), dtype=np.float32)
    taa = TemporalAntiAliasing()
    first = taa(a, still)
    np.testing.assert_array_equal(first, a)
    assert not np.shares_memory(first, a)
    first[:] = 0.0  # the caller owns the output: the history must not change
    assert np.abs(taa(a, still) - a).max() < 1e-6
    taa.reset()
    np.testing.assert_array_equal(taa(b, still), b)
    small = rng.random((8, 12, 3), dtype=np.float32)
    np.testing.assert_array_equal(taa(small, np.zeros((8, 12, 2), dtype=np.float32)), small)


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="history_weight"):
        TemporalAntiAliasing(history_weight=1.0)
    with pytest.raises(ValueError, match="clamp"):
        TemporalAntiAliasing(clamp="box")
    with pytest.raises(ValueError, match="reprojection"):
        TemporalAntiAliasing(reprojection="lanczos")
    with pytest.raises(ValueError, match="motion"):
        TemporalAntiAliasing()(np.zeros((4, 4, 3), dtype=np.float32), np.zeros((4, 5, 2), dtype=np.float32))
