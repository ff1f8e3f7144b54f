"""Depth slabs (``RayCaster.render(..., slabs=K)``): the same pass cut into K depth slabs, each composited apart."""
from __future__ import annotations

import numpy as np
import pytest
from test_render_reference import oblique_volume, shaded_tf

from volsr_core.render import RayCaster
from volsr_core.render.layout import OUT_CHANNELS, OUT_DEPTH
from volsr_core.render.slabs import composited, mixed_share
from volsr_core.scene import Camera, TransferFunction, Volume

FEATURES = slice(OUT_DEPTH, OUT_CHANNELS)  # a frame's channels after its colour and alpha


def composite(slabs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied RGB and alpha of (K, H, W, 6) slabs composited front to back."""
    colour, transmittance = np.zeros(slabs.shape[1:3] + (3,)), np.ones(slabs.shape[1:3] + (1,))
    for slab in slabs.astype(np.float64):
        colour += transmittance * slab[..., :3]
        transmittance *= 1.0 - slab[..., 3:4]
    return colour, 1.0 - transmittance[..., 0]


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("n_slabs", [1, 3])
def test_the_slabs_composite_to_the_frame(parallel, n_slabs):
    volume = oblique_volume()
    caster = RayCaster(volume, shaded_tf(), block_size=4, background=(0.2, 0.3, 0.4), start_jitter="ign")
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1),
                            parallel_projection=parallel).zoom(1.5)
    frame = caster.render(camera, 24, 20, jitter=(0.2, -0.3), previous_camera=camera.azimuth(3), seed=5,
                          slabs=n_slabs)
    assert frame.slabs.shape == (n_slabs, 20, 24, 6)
    colour, alpha = composite(frame.slabs)
    assert frame.alpha.max() > 0.5, "scene must be visible"
    np.testing.assert_allclose(alpha, frame.alpha, atol=1e-5)
    np.testing.assert_allclose(colour + (1.0 - alpha[..., None]) * (0.2, 0.3, 0.4), frame.color, atol=1e-5)
    if n_slabs == 3:
        assert sum((frame.slabs[k, ..., 3] > 1e-3).any() for k in range(3)) >= 2, "the volume must span slabs"
    assert caster.render(camera, 24, 20).slabs is None


def test_one_slab_moves_with_the_opacity_weighted_mean_point():
    volume = oblique_volume()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(1.5)
    kwargs = dict(jitter=(0.1, 0.2), previous_camera=camera.azimuth(4).elevation(2), seed=2)
    frame = RayCaster(volume, shaded_tf(), motion_depth="mean").render(camera, 16, 16, slabs=1, **kwargs)
    shown = frame.alpha > 1e-3
    assert shown.mean() > 0.3
    np.testing.assert_allclose(frame.slabs[0, ..., 4:6][shown], frame.motion[shown], atol=1e-4)
    assert np.all(frame.slabs[0, ..., 4:6][~(frame.slabs[0, ..., 3] > 0)] == 0.0)


def test_slabs_composited_into_one_give_the_frames_alpha_and_their_seen_motion():
    """:func:`~volsr_core.render.slabs.composited` of a render in three slabs: the frame's alpha and premultiplied
    colour; on made-up slabs, the motion weighted by what each slab adds to the composite's alpha, 0 where none
    shows."""
    volume = oblique_volume()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(1.5)
    frame = RayCaster(volume, shaded_tf(), background=(0.2, 0.3, 0.4)).render(camera, 24, 20, slabs=3)
    one = composited(frame.slabs)
    assert one.shape == (1, 20, 24, 6) and one.dtype == np.float32 and frame.alpha.max() > 0.5
    np.testing.assert_allclose(one[0, ..., 3], frame.alpha, atol=1e-5)
    np.testing.assert_allclose(one[0, ..., :3] + (1.0 - one[0, ..., 3:4]) * (0.2, 0.3, 0.4), frame.color, atol=1e-5)
    slabs = np.zeros((2, 1, 3, 6), dtype=np.float32)
    slabs[0, 0, 0] = (0.1, 0.1, 0.1, 0.5, 1.0, 0.0)  # half opaque in front, moving right ...
    slabs[1, 0, 0] = (0.4, 0.4, 0.4, 1.0, 0.0, 2.0)  # ... an opaque back moving down, half of it seen
    slabs[1, 0, 1] = (0.3, 0.3, 0.3, 0.6, -1.0, 1.0)  # the back alone
    one = composited(slabs)[0, 0]
    np.testing.assert_allclose(one[0], (0.3, 0.3, 0.3, 1.0, 0.5, 1.0), atol=1e-6)
    np.testing.assert_allclose(one[1], slabs[1, 0, 1], atol=1e-6)
    assert np.all(one[2] == 0.0)


def test_the_mixed_share_counts_the_shown_pixels_where_two_slabs_each_add_to_the_composite():
    """:func:`~volsr_core.render.slabs.mixed_share`: counted on made-up slabs (a slab seen through an opaque front adds
    nothing; one behind an empty front mixes with nothing), 0 for one slab or nothing shown; on two plates, none with
    the back plate hidden behind an opaque front and most pixels with two alike faint ones; on two cubes, none where
    the view shows them side by side and a good part once it has turned to line them up."""
    slabs = np.zeros((3, 2, 3, 6), dtype=np.float32)
    slabs[0, 0, :, 3] = (0.5, 1.0, 0.0)  # front: half, opaque, empty
    slabs[1, 0, :, 3] = (0.2, 1.0, 1.0)  # middle: seen at 0.1, hidden, alone
    slabs[2, 0, 0, 3] = 0.06  # back: seen at 0.06 * 0.4 = 0.024, too little
    assert mixed_share(slabs) == pytest.approx(1 / 3)  # three shown pixels, the first mixes two slabs
    assert mixed_share(slabs, seen=0.2) == 0.0
    slabs[1, 1, 0, 3] = slabs[2, 1, 0, 3] = 0.5  # a fourth pixel shown: 0.5 and 0.25 added
    assert mixed_share(slabs) == pytest.approx(2 / 4)
    assert mixed_share(slabs[:1]) == 0.0 and mixed_share(np.zeros_like(slabs)) == 0.0
    camera = Camera.framing(plates(True, True).bounds, direction=(0.05, 0.1, 1.0), view_up=(0, 1, 0)).zoom(1.3)
    white = [[0.0, 1.0, 1.0, 1.0], [500.0, 1.0, 1.0, 1.0]]
    opaque_front = TransferFunction(color=white, scalar_opacity=[[250.0, 0.0], [300.0, 0.3], [500.0, 1.0]])
    alike = TransferFunction(color=white, scalar_opacity=[[250.0, 0.0], [300.0, 0.1], [500.0, 0.1]])
    hidden = RayCaster(plates(True, True), opaque_front).render(camera, 16, 16, slabs=2).slabs
    both = RayCaster(plates(True, True), alike).render(camera, 16, 16, slabs=2).slabs
    assert (hidden[1, ..., 3] > 0.1).mean() > 0.2, "the back plate is in the back slab, hidden or not"
    assert mixed_share(hidden) == 0.0 and mixed_share(both) > 0.5
    side_by_side = Camera.framing(cubes().bounds, direction=(0.0, 0.0, 1.0), view_up=(0, 1, 0))
    shares = [mixed_share(RayCaster(cubes(), faint_white()).render(c, 32, 32, slabs=2).slabs)
              for c in (side_by_side, side_by_side.azimuth(45.0))]
    assert shares[0] == 0.0 and shares[1] > 0.3, shares  # measured: 0.0 and 0.67


def cubes() -> Volume:
    """Two 8-voxel cubes (value 500) in a 40³ volume, one near the front left, one at the back right as seen along z:
    side by side from there, lined up along the view turned 45° about y."""
    array = np.zeros((40, 40, 40), dtype=np.float32)
    array[4:12, 16:24, 4:12] = 500.0
    array[28:36, 16:24, 28:36] = 500.0
    return Volume(array, spacing=(1.0, 1.0, 1.0))


def faint_white() -> TransferFunction:
    """White, faint from 300 up: a cube seen through another shows."""
    return TransferFunction(color=[[0.0, 1.0, 1.0, 1.0], [500.0, 1.0, 1.0, 1.0]],
                            scalar_opacity=[[250.0, 0.0], [300.0, 0.05], [500.0, 0.05]])


def plates(front: bool, back: bool) -> Volume:
    """Two semi-transparent plates across a 40³ volume, 22 voxels apart along z (values 500 and 300)."""
    array = np.zeros((40, 40, 40), dtype=np.float32)
    if front:
        array[8:10, 5:35, 5:35] = 500.0
    if back:
        array[30:32, 5:35, 5:35] = 300.0
    return Volume(array, spacing=(1.0, 1.0, 1.0))


def test_two_plates_fall_into_two_slabs_each_as_if_rendered_alone():
    """Two plates, each in a slab of its own: each slab holds what a render of its plate alone holds, unattenuated
    by the plate in front, and moves as that plate's own opacity-weighted mean point does."""
    tf = TransferFunction(color=[[0, 0, 0, 0], [300, 1.0, 0.2, 0.1], [500, 0.1, 0.3, 1.0]],
                          scalar_opacity=[[0, 0.0], [250, 0.0], [300, 0.3], [500, 0.5]])
    camera = Camera.framing(plates(True, True).bounds, direction=(0.05, 0.1, 1.0), view_up=(0, 1, 0)).zoom(1.3)
    kwargs = dict(jitter=(0.25, -0.25), previous_camera=camera.azimuth(5))
    both = RayCaster(plates(True, True), tf, motion_depth="mean").render(camera, 20, 20, slabs=2, **kwargs)
    for k, alone in enumerate((plates(True, False), plates(False, True))):
        frame = RayCaster(alone, tf, motion_depth="mean").render(camera, 20, 20, **kwargs)
        shown = frame.alpha > 1e-3
        assert shown.mean() > 0.15 and frame.alpha.max() > 0.2
        np.testing.assert_allclose(both.slabs[k, ..., 3], frame.alpha, atol=1e-5)
        np.testing.assert_allclose(both.slabs[k, ..., :3], frame.color, atol=1e-5)  # black background
        np.testing.assert_allclose(both.slabs[k, ..., 4:6][shown], frame.motion[shown], atol=1e-4)
    parallax = np.abs(both.slabs[0, ..., 4] - both.slabs[1, ..., 4])[both.slabs[1, ..., 3] > 1e-3]
    assert parallax.mean() > 0.5, "the plates must move apart, or the test shows nothing"


def test_slabs_leave_the_frames_features_as_they_are_and_its_colour_within_what_early_termination_drops():
    """Behind an opaque front the ray marches on through the hidden slabs (at a longer step): the features are
    those of a render without slabs, and colour and alpha differ by at most the light early termination drops."""
    volume = oblique_volume()
    caster = RayCaster(volume, shaded_tf(), early_termination=0.8, start_jitter="ign")
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(1.5)
    kwargs = dict(jitter=(0.2, -0.3), previous_camera=camera.azimuth(3), seed=4)
    plain, layered = caster.render(camera, 24, 20, **kwargs), caster.render(camera, 24, 20, slabs=3, **kwargs)
    terminated = plain.alpha >= 0.8
    assert terminated.mean() > 0.03, "the front must end rays, or the test shows nothing"
    assert (layered.slabs[1:, ..., 3][:, terminated] > 1e-3).any(), "the slabs behind must hold something"
    np.testing.assert_array_equal(layered.data[..., FEATURES], plain.data[..., FEATURES])
    assert np.abs(layered.data[..., :4] - plain.data[..., :4]).max() <= 0.2 + 1e-6
    np.testing.assert_array_equal(layered.data[~terminated], plain.data[~terminated])


def test_a_front_slab_opaque_by_itself_leaves_the_features_as_they_are():
    """Where the front slab turns opaque on its own, the ray jumps to the slab behind, whose first sample (here more
    opaque than any in front) it takes at the full step: a render without slabs ends the ray in front and never sees
    that sample, and nor do the features."""
    array = np.zeros((40, 40, 40), dtype=np.float32)
    array[2:20, 5:35, 5:35], array[20:38, 5:35, 5:35] = 500.0, 800.0  # a dense front block, a denser one behind
    volume = Volume(array, spacing=(1.0, 1.0, 1.0))
    tf = TransferFunction(color=[[0, 0, 0, 0], [500, 0.1, 0.3, 1.0], [800, 1.0, 0.2, 0.1]],
                          scalar_opacity=[[0, 0.0], [400, 0.0], [500, 0.6], [800, 0.95]])
    caster = RayCaster(volume, tf, start_jitter="ign")
    camera = Camera.framing(volume.bounds, direction=(0.05, 0.1, 1.0), view_up=(0, 1, 0)).zoom(1.3)
    kwargs = dict(jitter=(0.2, -0.3), previous_camera=camera.azimuth(3), seed=1)
    plain, layered = caster.render(camera, 20, 20, **kwargs), caster.render(camera, 20, 20, slabs=2, **kwargs)
    front_opaque = layered.slabs[0, ..., 3] >= 0.99
    assert front_opaque.mean() > 0.3, "the front slab must turn opaque on its own, or the test shows nothing"
    assert (layered.slabs[1, ..., 3][front_opaque] > 0.5).mean() > 0.8, "the slab behind must hold the block behind"
    np.testing.assert_array_equal(layered.data[..., FEATURES], plain.data[..., FEATURES])


def test_bad_slab_counts_are_rejected():
    caster = RayCaster(plates(True, True), shaded_tf())
    camera = Camera.framing(plates(True, True).bounds)
    for bad in (-1, 1.5):
        with pytest.raises(ValueError, match="slabs"):
            caster.render(camera, 4, slabs=bad)
