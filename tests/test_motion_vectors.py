"""Motion vectors: backward-warping frame t-1 with frame t's vectors reproduces frame t."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.temporal import backward_warp


def psnr_where(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / np.mean((a[mask] - b[mask]) ** 2)))


@pytest.fixture(scope="module")
def orbit_pair():
    """Frames t-1 and t of the phantom, 256², the camera orbiting 2 degrees between them; motion vectors
    reproject the max-alpha point, which is also the ``position`` feature."""
    volume = Volume.from_record(make_phantom())
    caster = RayCaster(volume, get_preset("CT-Soft-Tissue"), motion_depth="max_alpha")
    previous = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.2)).zoom(1.6)
    current = previous.azimuth(2.0).reset_clipping_range(volume.bounds)
    return caster.render(previous, 256), caster.render(current, 256, previous_camera=previous)


def test_warped_previous_colour_matches_the_current_frame(orbit_pair):
    frame_prev, frame = orbit_pair
    warped, valid = backward_warp(frame_prev.color, frame.motion)
    mask = (frame.alpha > 0.5) & valid
    assert mask.mean() > 0.2, "the surface must cover a good part of the image"
    assert np.abs(frame.motion[mask]).max() > 2.0, "the camera move must shift pixels noticeably"
    warped_psnr = psnr_where(warped, frame.color, mask)
    unwarped_psnr = psnr_where(frame_prev.color, frame.color, mask)
    print(f"PSNR over alpha > 0.5: warped {warped_psnr:.1f} dB, not warped {unwarped_psnr:.1f} dB")
    assert warped_psnr >= 30.0
    assert warped_psnr >= unwarped_psnr + 3.0


def test_warped_previous_positions_land_on_the_current_surface(orbit_pair):
    """Geometry alone: where the same surface is seen, the warped world position is the current one.

    The max-alpha sample lies on the ray's sample grid, so positions agree to about half a
    sample step (0.375 mm here), not exactly.
    """
    frame_prev, frame = orbit_pair
    warped, valid = backward_warp(frame_prev.position, frame.motion)
    mask = (frame.alpha > 0.5) & valid
    moved = np.linalg.norm(warped - frame.position, axis=-1)[mask]
    still = np.linalg.norm(frame_prev.position - frame.position, axis=-1)[mask]
    print(f"median position error: warped {np.median(moved):.3f} mm, not warped {np.median(still):.3f} mm")
    assert np.median(moved) < 0.5 * 0.75
    assert np.median(still) > 3 * np.median(moved)


def test_motion_is_zero_without_a_previous_camera_and_for_a_static_one():
    volume = Volume.from_record(make_phantom(shape=(48, 48, 48)))
    caster = RayCaster(volume, get_preset("CT-Phantom"))
    camera = Camera.framing(volume.bounds)
    assert np.all(caster.render(camera, 32).motion == 0)
    still = caster.render(camera, 32, jitter=(0.3, -0.2), previous_camera=camera)
    assert np.abs(still.motion).max() < 1e-3  # vectors exclude jitter
