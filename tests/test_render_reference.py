"""The CPU kernel against a plain float64 per-ray reference, and against analytic answers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from render_reference import render_reference
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, TransferFunction, Volume
from volsr_core.temporal import render_supersampled


def smooth_volume(shape=(11, 10, 9), seed=3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    z, y, x = np.meshgrid(*[np.linspace(-1, 1, n) for n in shape], indexing="ij")
    field = 600 * np.exp(-3 * (x**2 + (y - 0.2) ** 2 + z**2)) + 300 * np.sin(3 * x + 2 * z)
    return (field + rng.normal(0, 20, shape)).astype(np.float32)


def oblique_volume() -> Volume:
    """Anisotropic spacing and rotated direction cosines, so index/world mix-ups show."""
    c, s = math.cos(0.4), math.sin(0.4)
    direction = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, 0.8, -0.6], [0, 0.6, 0.8]])
    return Volume(smooth_volume(), spacing=(1.2, 0.9, 1.6), origin=(-5, -4, -8), direction=direction)


def shaded_tf(gradient_opacity=True) -> TransferFunction:
    return TransferFunction(
        color=[[-300, 0.1, 0.2, 0.9], [100, 0.9, 0.4, 0.1], [700, 1.0, 1.0, 0.8]],
        scalar_opacity=[[-200, 0.0], [150, 0.15], [500, 0.6], [800, 0.9]],
        gradient_opacity=[[0, 0.3], [60, 1.0]] if gradient_opacity else None,
        shade=True, ambient=0.2, diffuse=0.7, specular=0.4, specular_power=12, scalar_opacity_unit_distance=2.0)


@pytest.mark.parametrize("parallel", [False, True])
def test_every_buffer_matches_the_float64_reference(parallel):
    volume = oblique_volume()
    tf = shaded_tf()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1),
                            parallel_projection=parallel).zoom(2.0)
    previous = camera.azimuth(4).elevation(-3)
    w, h, step, jitter = 14, 11, 0.4, (0.23, -0.31)
    caster = RayCaster(volume, tf, sample_distance=step, block_size=4)
    frame = caster.render(camera, w, h, jitter=jitter, previous_camera=previous)
    ref = render_reference(volume, tf, camera, w, h, step, jitter=jitter, previous=previous)
    assert ref["alpha"].max() > 0.5 and (ref["alpha"] > 0.05).mean() > 0.4 and (ref["alpha"] == 0).any(), \
        "the scene must have hits and misses"
    for name in ("color", "alpha", "depth", "max_rgba", "position", "motion"):
        err = np.abs(getattr(frame, name) - ref[name])
        assert err.mean() <= 1e-3, f"{name}: mean abs error {err.mean():.2e}"


@pytest.mark.parametrize("start_jitter", [False, "ign"])
def test_the_colour_only_program_renders_the_same_colour(start_jitter):
    """render_color (native rendering's program: no feature tracking) against render's colour, bit for bit, and the
    float64 reference; shaded with gradient opacity, jittered rays, a reused buffer."""
    volume, tf = oblique_volume(), shaded_tf()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(2.0)
    caster = RayCaster(volume, tf, sample_distance=0.4, block_size=4, start_jitter=start_jitter,
                       background=(0.1, 0.2, 0.3))
    buffer = np.full((11, 14, 3), np.nan, np.float32)
    for seed, jitter in ((0, (0.0, 0.0)), (5, (0.23, -0.31))):
        colour = caster.render_color(camera, 14, 11, jitter=jitter, seed=seed, out=buffer)
        assert colour is buffer and colour.shape == (11, 14, 3) and colour.dtype == np.float32
        assert np.array_equal(colour, caster.render(camera, 14, 11, jitter=jitter, seed=seed).color)
    if not start_jitter:
        ref = render_reference(volume, tf, camera, 14, 11, 0.4, jitter=(0.23, -0.31), background=(0.1, 0.2, 0.3))
        assert np.abs(colour - ref["color"]).mean() <= 1e-3
    with pytest.raises(ValueError, match="image size must be positive"):
        caster.render_color(camera, 0, 11)


@pytest.mark.parametrize("motion_depth", ["max_alpha", "threshold", "mean"])
def test_motion_vectors_reproject_the_chosen_point(motion_depth):
    """P_DEPTH_MODE: the motion vectors (and motion_depth) follow the chosen point; the max-alpha
    features (depth, position, max_rgba) do not change with it."""
    volume = oblique_volume()
    tf = shaded_tf()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(2.0)
    previous = camera.azimuth(4).elevation(-3)
    w, h, step, jitter = 14, 11, 0.4, (0.23, -0.31)
    caster = RayCaster(volume, tf, sample_distance=step, block_size=4, motion_depth=motion_depth,
                       depth_threshold=0.4)
    frame = caster.render(camera, w, h, jitter=jitter, previous_camera=previous)
    ref = render_reference(volume, tf, camera, w, h, step, jitter=jitter, previous=previous,
                           motion_depth=motion_depth, depth_threshold=0.4)
    for name in ("motion", "motion_depth", "depth", "position", "max_rgba"):
        err = np.abs(getattr(frame, name) - ref[name])
        assert err.mean() <= 1e-3, f"{name}: mean abs error {err.mean():.2e}"
    if motion_depth != "max_alpha":
        paper = RayCaster(volume, tf, sample_distance=step, block_size=4, motion_depth="max_alpha").render(
            camera, w, h, jitter=jitter, previous_camera=previous)
        assert np.abs(paper.motion - frame.motion).max() > 0.05, "the choice must matter in this scene"
        np.testing.assert_array_equal(paper.depth, frame.depth)


def test_empty_space_skipping_changes_nothing():
    volume = oblique_volume()
    tf = TransferFunction(color=[[0, 1, 1, 1]], scalar_opacity=[[400, 0.0], [600, 0.8]])  # most bricks empty
    camera = Camera.framing(volume.bounds, direction=(0.2, 1.0, 0.1))
    with_skip = RayCaster(volume, tf, block_size=2).render(camera, 24, 20)
    without = RayCaster(volume, tf, empty_space_skipping=False).render(camera, 24, 20)
    assert with_skip.alpha.max() > 0.3
    np.testing.assert_allclose(with_skip.data, without.data, atol=1e-6)


def test_homogeneous_slab_alpha_is_one_minus_exp_minus_k_length():
    # 40 voxels along z, spacing 1 mm: the orthographic rays along z cross L = 39 mm of medium
    volume = Volume(np.full((40, 16, 16), 100.0, dtype=np.float32), spacing=(1.0, 1.0, 1.0))
    a_unit, unit = 0.05, 1.0  # opacity per mm
    tf = TransferFunction(color=[[0, 1, 1, 1], [200, 1, 1, 1]], scalar_opacity=[[0, a_unit], [200, a_unit]],
                          scalar_opacity_unit_distance=unit)
    camera = Camera.framing(volume.bounds, direction=(0, 0, 1), view_up=(0, -1, 0), parallel_projection=True).zoom(3)
    step = 0.01
    frame = RayCaster(volume, tf, sample_distance=step, early_termination=1.0).render(camera, 8, 8)
    k = -math.log(1.0 - a_unit) / unit
    expected = 1.0 - math.exp(-k * 39.0)
    # N samples of length `step` cover L + step at most: the alpha may exceed by k*exp(-kL)*step
    assert np.all(np.abs(frame.alpha - expected) <= k * math.exp(-k * 39.0) * step + 1e-4)


def test_ray_start_jitter_removes_wood_grain_from_a_supersampled_render():
    """A thin translucent spherical shell (1.5 mm) seen along an axis with a 2 mm step: with every ray
    starting on the same planes, whether a sample lands in the shell depends on where the shell crosses
    the sample grid, a pattern of rings ("wood grain") that averaging sub-pixel jitter keeps. Starting
    each ray at a per-pixel, per-sample offset (interleaved gradient noise) turns it into noise that
    the average removes. Both against the same shell marched at a 0.05 mm step, same pixel samples."""
    n, spacing, radius, half_width = 64, 0.5, 12.0, 0.75  # mm
    z, y, x = np.mgrid[:n, :n, :n].astype(np.float32)
    centre = (n - 1) / 2
    dist = np.sqrt((x - centre) ** 2 + (y - centre) ** 2 + (z - centre) ** 2) * spacing  # mm from the centre
    volume = Volume(dist.astype(np.float32), spacing=(spacing,) * 3)
    lo, hi = radius - half_width, radius + half_width
    shell = [[lo - 0.01, 0.0], [lo, 0.1], [hi, 0.1], [hi + 0.01, 0.0]]  # opacity 0.1 per mm inside the shell
    tf = TransferFunction(color=[[0, 1, 1, 1]], scalar_opacity=shell, scalar_opacity_unit_distance=1.0)
    camera = Camera.framing(volume.bounds, direction=(0, 0, 1), view_up=(0, -1, 0), parallel_projection=True)
    errors = {}
    for spp in (4, 16):
        reference = render_supersampled(RayCaster(volume, tf, sample_distance=0.05, early_termination=1.0),
                                        camera, 64, spp=spp)
        for start_jitter in (False, "ign"):
            caster = RayCaster(volume, tf, sample_distance=2.0, early_termination=1.0, start_jitter=start_jitter)
            image = render_supersampled(caster, camera, 64, spp=spp)
            errors[start_jitter, spp] = float(np.sqrt(np.mean((image - reference) ** 2)))
    print("RMS error against the fine step:", {k: round(v, 4) for k, v in errors.items()})
    assert errors[False, 16] > 0.01, "the coarse step must leave visible rings with a fixed start"
    assert errors[False, 16] > 0.7 * errors[False, 4], "a fixed start's rings do not average away"
    assert errors["ign", 16] < 0.6 * errors["ign", 4], "jittered starts' noise falls with the samples"
    assert errors["ign", 16] < errors[False, 16] / 2


def test_sphere_silhouette_lands_where_projection_predicts():
    n, radius = 48, 15.0
    z, y, x = np.mgrid[:n, :n, :n].astype(np.float32)
    centre = (n - 1) / 2
    dist = np.sqrt((x - centre) ** 2 + (y - centre) ** 2 + (z - centre) ** 2)
    volume = Volume(np.clip(radius + 0.5 - dist, -1, 1).astype(np.float32) * 1000, spacing=(0.7, 0.7, 0.7),
                    origin=(10.0, -20.0, 5.0))
    tf = TransferFunction(color=[[0, 1, 1, 1]], scalar_opacity=[[-1, 0.0], [0, 0.0], [1, 1.0], [1000, 1.0]])
    camera = Camera.framing(volume.bounds, direction=(1.0, 0.5, -0.3), view_up=(0, 0, 1)).zoom(1.6)
    w, h = 96, 72
    frame = RayCaster(volume, tf).render(camera, w, h)
    # predicted: rays whose distance to the sphere's centre is below its radius (mm)
    c_world = volume.center
    r_mm = radius * 0.7
    ys, xs = np.mgrid[0:h, 0:w]
    predicted = np.zeros((h, w), bool)
    margin = np.zeros((h, w), bool)
    for yy, xx in zip(ys.ravel(), xs.ravel()):
        o, d = camera.ray(xx + 0.5, yy + 0.5, w, h)
        miss = np.linalg.norm(np.cross(c_world - o, d))
        predicted[yy, xx] = miss < r_mm
        margin[yy, xx] = abs(miss - r_mm) < 1.0 * 0.7  # within one voxel of the silhouette
    rendered = frame.alpha > 0.5
    assert predicted.sum() > 500
    assert not np.any((rendered != predicted) & ~margin), "silhouette pixels off the predicted disc"


def test_a_frame_knows_how_many_pixels_a_voxel_spans_at_the_focal_point():
    """The oblique volume's smallest spacing (0.9 mm) against the pixel size on the focal plane; ``zoom``
    scales it, and so does the image size."""
    volume = oblique_volume()
    caster = RayCaster(volume, shaded_tf())
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.2), view_up=(0, 0, 1))
    frame = caster.render(camera, 40, 30)
    assert frame.pixels_per_voxel == pytest.approx(0.9 / camera.pixel_size_at_focus(30), rel=1e-12)
    assert caster.render(camera.zoom(2.0), 40, 30).pixels_per_voxel == pytest.approx(
        0.9 / camera.zoom(2.0).pixel_size_at_focus(30), rel=1e-12)
    assert caster.render(camera, 80, 60).pixels_per_voxel == pytest.approx(2 * frame.pixels_per_voxel, rel=1e-12)
