"""Temporal upsampling (TAAU): conventions (jitter, motion), convergence, disocclusion, the history cap, a
CT_AVM orbit against single-frame upscaling."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.temporal import halton_jitter, jitter_phases
from volsr_core.temporal.color import (
    box_minmax, clip_to_box, fetch_catmull_rom, image_to_ycocg, on_screen, to_rgb, to_ycocg,
)
from volsr_core.temporal.jitter import sample_offset
from volsr_core.temporal.taau import TemporalUpsampler, view_rotation


def pattern(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth colour pattern of continuous HR coordinates (pixel units)."""
    return np.stack([0.5 + 0.4 * np.sin(0.31 * x + 0.2 * y), 0.5 + 0.4 * np.cos(0.23 * y - 0.11 * x),
                     0.5 + 0.3 * np.sin(0.17 * (x + y))], axis=-1).astype(np.float32)


def truth(hr: int, shift: float = 0.0, spp: int = 8) -> np.ndarray:
    """The pattern box-filtered over each HR pixel (spp x spp samples), moved right by ``shift`` HR px."""
    ys, xs = np.mgrid[0:hr, 0:hr].astype(np.float64)
    acc = np.zeros((hr, hr, 3))
    for i in range(spp):
        for j in range(spp):
            acc += pattern(xs + (i + 0.5) / spp - shift, ys + (j + 0.5) / spp)
    return (acc / spp ** 2).astype(np.float32)


def lr_frame(lr: int, scale: int, jitter, shift: float = 0.0) -> np.ndarray:
    """Point samples at the jittered LR positions, in HR coordinates, the pattern moved by ``shift``."""
    ys, xs = np.mgrid[0:lr, 0:lr].astype(np.float64)
    return pattern((xs + 0.5 + jitter[0]) * scale - shift, (ys + 0.5 + jitter[1]) * scale)


def psnr(a, b):
    return float(10 * np.log10(1.0 / np.mean((a.astype(np.float64) - b) ** 2)))


def test_a_constant_image_stays_constant_under_any_motion_and_jitter():
    rng = np.random.default_rng(1)
    up = TemporalUpsampler(2)
    lr = np.full((9, 11, 3), 0.37, dtype=np.float32)
    for k in range(5):
        motion = rng.uniform(-2, 2, (9, 11, 2)).astype(np.float32)
        out = up(lr, motion, halton_jitter(k, 32), rng.random((9, 11)).astype(np.float32), rotation=2.0 * (k % 2))
        assert out.shape == (18, 22, 3)
        np.testing.assert_allclose(out, 0.37, atol=1e-5)


@pytest.mark.parametrize("scale", [2, 4, 8, 16])
def test_a_still_camera_converges_towards_the_box_filtered_image(scale):
    """At 8x and 16x a still view's narrow splat falls below float32's range far from the samples: the nearest sample
    takes the weight there (``SPLAT_FLOOR``), where the sums made NaN that spread through the history."""
    lr_size = 64 // scale
    ref = truth(64)
    up = TemporalUpsampler(scale)
    still = np.zeros((lr_size, lr_size, 2), dtype=np.float32)
    scores = []
    for k in range(8 * scale * scale):
        jitter = halton_jitter(k, jitter_phases(scale))
        out = up(lr_frame(lr_size, scale, jitter), still, jitter, rotation=0.0)
        assert np.isfinite(out).all()
        scores.append(psnr(out[8:-8, 8:-8], ref[8:-8, 8:-8]))
    print(f"x{scale}: first frame {scores[0]:.1f} dB, last {scores[-1]:.1f} dB")
    assert scores[-1] > scores[0] + 6.0
    assert scores[-1] > 35.0


def test_a_pan_reprojects_the_history_with_the_motion_vectors():
    """The pattern moves right 1.5 HR px per frame: vectors (-0.75 LR px, 0) fetch the history; the
    wrong sign (or none) does worse than right."""
    scale, lr_size, speed = 2, 32, 1.5
    results = {}
    for label, sign in (("right", 1.0), ("flipped", -1.0), ("none", 0.0)):
        up = TemporalUpsampler(scale)
        motion = np.zeros((lr_size, lr_size, 2), dtype=np.float32)
        motion[..., 0] = -sign * speed / scale
        for k in range(16):
            jitter = halton_jitter(k, jitter_phases(scale))
            out = up(lr_frame(lr_size, scale, jitter, shift=k * speed), motion if k else motion * 0, jitter,
                     rotation=0.0)
        results[label] = psnr(out[8:-8, 8:-8], truth(64, shift=15 * speed)[8:-8, 8:-8])
    print(results)
    assert results["right"] > results["flipped"] + 3.0
    assert results["right"] > results["none"] + 3.0
    assert results["right"] > 33.0


def test_the_history_is_dropped_where_a_nearer_surface_moved_away_and_the_neighbourhood_shows_parallax():
    scale, n = 2, 12
    up = TemporalUpsampler(scale)
    motion = np.zeros((n, n, 2), dtype=np.float32)
    red = np.zeros((n, n, 3), dtype=np.float32)
    red[..., 0] = 1.0
    near = np.full((n, n), 0.2, dtype=np.float32)
    up(red, motion, (0.0, 0.0), near, rotation=0.0)
    # now the background (depth 0.9) shows; its left half moves (parallax against the right half)
    blue = np.zeros((n, n, 3), dtype=np.float32)
    blue[..., 2] = 1.0
    moving = motion.copy()
    moving[:, : n // 2, 0] = 1.0
    far = np.full((n, n), 0.9, dtype=np.float32)
    out = up(blue, moving, (0.0, 0.0), far, rotation=2.0)
    # at the parallax edge the red history is dropped; far from it (uniform motion) the depth test
    # is off and only the colour clamp (a blue 3x3 box) acts - which also rejects red here
    np.testing.assert_allclose(out[:, n - 2:n + 2], np.broadcast_to([0, 0, 1], (2 * n, 4, 3)), atol=1e-6)
    assert np.all(up.history[:, n - 2:n + 2, 3] <= 1.0)


def test_the_cap_falls_with_the_view_rotation():
    scale, n = 2, 8
    lr = np.random.default_rng(2).random((n, n, 3), dtype=np.float32)
    motion = np.full((n, n, 2), 0.01, dtype=np.float32)
    for rotation, cap in ((2.0, 0.5), (5.0, 2.0 / 8.5)):
        up = TemporalUpsampler(scale)
        for k in range(6):
            up(lr, motion, halton_jitter(k, 32), rotation=rotation)
        assert up.history[..., 3].max() == pytest.approx(cap, rel=1e-5)
    up = TemporalUpsampler(scale)
    for k in range(40):
        up(lr, motion * 0, halton_jitter(k, 32), rotation=0.0)
    assert up.history[..., 3].max() > 4.0, "a still camera accumulates a long history"


def test_view_rotation_is_the_angle_between_the_directions_of_projection():
    from volsr_core.scene import Camera

    camera = Camera(position=(0, -100, 0), focal_point=(0, 0, 0), view_up=(0, 0, 1))
    assert view_rotation(camera, None) == 0.0
    assert view_rotation(camera.azimuth(3.0), camera) == pytest.approx(3.0, abs=1e-6)
    panned = Camera(position=(10, -100, 0), focal_point=(10, 0, 0), view_up=(0, 0, 1))
    assert view_rotation(panned, camera) == pytest.approx(0.0, abs=1e-6)


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="scale"):
        TemporalUpsampler(0)
    up = TemporalUpsampler(2)
    with pytest.raises(ValueError, match="jitter"):
        up(np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 2), np.float32), (0.5, 0.0))
    with pytest.raises(ValueError, match="depth"):
        up(np.zeros((4, 4, 3), np.float32), np.zeros((4, 4, 2), np.float32), (0.0, 0.0), np.zeros((3, 4)))


def test_an_estimate_written_into_out_is_the_one_returned_otherwise_frame_after_frame():
    """``out=`` (a buffer the caller reuses, as the XS upscaler does): the same values as a new image each frame, in
    that buffer; a buffer of another shape, type or layout is refused."""
    rng = np.random.default_rng(8)
    fresh, into = TemporalUpsampler(2), TemporalUpsampler(2)
    buffer = np.full((12, 10, 3), np.nan, np.float32)
    for t in range(4):
        colour, motion = rng.random((6, 5, 3), dtype=np.float32), rng.uniform(-1, 1, (6, 5, 2)).astype(np.float32)
        jitter = halton_jitter(t, jitter_phases(2))
        expected = fresh(colour, motion, jitter, rotation=2.0)
        assert into(colour, motion, jitter, rotation=2.0, out=buffer) is buffer
        np.testing.assert_array_equal(buffer, expected)
    for bad in (np.empty((12, 10, 4), np.float32), np.empty((12, 10, 3)), np.empty((10, 12, 3), np.float32).T):
        with pytest.raises(ValueError, match="out must be"):
            into(colour, motion, (0.0, 0.0), out=bad)


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


def test_the_renderers_channel_views_give_what_their_copies_give():
    """TAAU reads colour, motion and depth in place (strided views into the renderer's one buffer): the same
    frames as views and as contiguous copies, over a moving orbit, give identical outputs and side outputs;
    without side outputs, the same image."""
    from volsr_core.io import make_phantom
    from volsr_core.render import RayCaster
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit_around

    caster = RayCaster(Volume.from_record(make_phantom()), get_preset("CT-Phantom"), start_jitter="ign")
    in_place, copied, previous = TemporalUpsampler(2), TemporalUpsampler(2), None
    image_only = TemporalUpsampler(2, side_outputs=False)
    for t, camera in enumerate(orbit_around(caster.visible_bounds(), 4, 3.0)):
        frame = caster.render(camera, 24, 24, jitter=halton_jitter(t, jitter_phases(2)), previous_camera=previous,
                              seed=t)
        assert not frame.color.flags.c_contiguous and not frame.motion.flags.c_contiguous
        rotation = view_rotation(camera, previous)
        views = in_place(frame.color, frame.motion, frame.jitter, frame.motion_depth, rotation)
        copies = copied(frame.color.copy(), frame.motion.copy(), frame.jitter, frame.motion_depth.copy(), rotation)
        np.testing.assert_array_equal(views, copies)
        np.testing.assert_array_equal(in_place.last_aux, copied.last_aux)
        np.testing.assert_array_equal(image_only(frame.color, frame.motion, frame.jitter, frame.motion_depth,
                                                 rotation), views)
        assert image_only.last_aux is None
        previous = camera


def test_ct_avm_orbit_beats_single_frame_upscaling_at_2x_and_4x(ct_avm_path):
    """A 2 degree/frame orbit of CT_AVM (semi-transparent CT-AAA), 192² output, renderer motion vectors
    and motion depth: the last frames beat the unjittered LR render upscaled (what VTK shows)."""
    from volsr_core.render import RayCaster
    from volsr_core.scene import Volume, get_preset
    from volsr_core.scene.camera_paths import orbit_around
    from volsr_core.temporal import render_supersampled, upscale_bicubic, upscale_bilinear

    volume = Volume.load(ct_avm_path)
    caster = RayCaster(volume, get_preset("CT-AAA").placed_on(0.0, 446.0))
    cameras = orbit_around(caster.visible_bounds(), 12, 2.0)
    for scale in (2, 4):
        lr_size, taau, scores = 192 // scale, TemporalUpsampler(scale), []
        for i, camera in enumerate(cameras):
            jitter = halton_jitter(i, jitter_phases(scale))
            previous = cameras[i - 1] if i else None
            frame = caster.render(camera, lr_size, jitter=jitter, previous_camera=previous, seed=i)
            output = taau(frame.color, frame.motion, jitter, frame.motion_depth, view_rotation(camera, previous))
            if i < len(cameras) - 3:
                continue
            truth = render_supersampled(caster, camera, lr_size * scale, spp=16)
            centred = caster.render(camera, lr_size).color
            scores.append({"taau": psnr(output, truth), "bilinear": psnr(upscale_bilinear(centred, scale), truth),
                           "bicubic": psnr(np.clip(upscale_bicubic(centred, scale), 0, 1), truth)})
        for s in scores:
            print(f"CT_AVM {scale}x orbit: " + ", ".join(f"{k} {v:.2f} dB" for k, v in s.items()))
            assert s["taau"] >= max(s["bilinear"], s["bicubic"]) + 0.3


@pytest.mark.parametrize("scale", [2, 3, 4])
def test_one_halton_cycle_puts_samples_on_every_hr_pixel(scale):
    hits = {(sample_offset(jx, scale), sample_offset(jy, scale))
            for jx, jy in (halton_jitter(i, jitter_phases(scale)) for i in range(jitter_phases(scale)))}
    assert hits == {(x, y) for x in range(scale) for y in range(scale)}


def test_jitter_phases_follow_fsr2():
    assert [jitter_phases(s) for s in (1, 2, 3, 4)] == [8, 32, 72, 128]


def test_the_side_outputs_hold_the_reprojected_history_and_its_share_of_the_blend():
    scale, n = 2, 10
    rng = np.random.default_rng(8)
    up = TemporalUpsampler(scale)
    still = np.zeros((n, n, 2), dtype=np.float32)
    first = rng.random((n, n, 3), dtype=np.float32)
    up(first, still, (0.0, 0.0), rotation=0.0)
    assert np.all(up.last_aux == 0.0), "no history on the first frame: no colour, no share"
    history = up.history[..., :3].copy()
    second = np.full((n, n, 3), 0.4, dtype=np.float32)  # constant: the current estimate is 0.4 everywhere
    out = up(second, still, (0.25, -0.25), rotation=0.0)
    share = up.last_aux[..., 3]
    assert np.all((share > 0.0) & (share < 1.0))
    # the still camera: the history is read in place (Catmull-Rom at integer positions = the pixel itself),
    # no clamp when nothing moves
    np.testing.assert_allclose(up.last_aux[..., :3], history, atol=1e-5)
    # the output is the blend of the two by that share
    np.testing.assert_allclose(out, share[..., None] * history + (1.0 - share[..., None]) * 0.4, atol=1e-5)


@pytest.mark.parametrize("scale", [2, 4])
def test_the_history_is_the_catmull_rom_fetch_at_the_reprojected_position_clamped_into_the_lr_box(scale):
    """Per HR pixel, against the reference stages of temporal.color: the kernel's reprojected history
    (it slides its Catmull-Rom columns along the HR pixels of one LR sample) equals a 4x4 Catmull-Rom
    fetch of the previous history at (x, y) + scale * motion of the nearest LR sample, clamped into the
    YCoCg min/max box of that sample's 3x3 neighbourhood; image edges included. Parts of the frame are one colour
    (black, as the background around a volume, and another), where the kernel takes the box's colour without the
    fetch: the same values."""
    n = 9
    rng = np.random.default_rng(21)
    up = TemporalUpsampler(scale)
    still = np.zeros((n, n, 2), dtype=np.float32)
    up(rng.random((n, n, 3), dtype=np.float32), still, (0.0, 0.0), rotation=0.0)
    previous = up.history[..., :3].copy()
    lr = rng.random((n, n, 3), dtype=np.float32)
    lr[:, :3] = 0.0
    lr[5:, 5:] = (0.2, 0.5, 0.7)
    motion = rng.uniform(-1.5, 1.5, (n, n, 2)).astype(np.float32)
    motion[:, : n // 2] = motion[0, 0]  # runs of LR samples with equal motion, too
    jitter = (0.3, -0.2)
    up(lr, motion, jitter, rotation=0.0)
    ycocg = image_to_ycocg(lr)
    hr = n * scale
    checked = flat = 0
    for y in range(hr):
        ly = min(max(int(np.floor((y + 0.5) / scale - 0.5 - jitter[1] + 0.5)), 0), n - 1)
        for x in range(hr):
            lx = min(max(int(np.floor((x + 0.5) / scale - 0.5 - jitter[0] + 0.5)), 0), n - 1)
            sx, sy = x + scale * motion[ly, lx, 0], y + scale * motion[ly, lx, 1]
            if up.last_aux[y, x, 3] == 0.0:
                assert not on_screen(sx, sy, hr, hr)
                continue
            fetched = np.empty(3)
            fetch_catmull_rom(previous, sx, sy, fetched)
            lo, hi = box_minmax(ycocg, lx, ly)
            expected = to_rgb(*clip_to_box(to_ycocg(*fetched), lo, hi, False))
            np.testing.assert_allclose(up.last_aux[y, x, :3], expected, atol=2e-6)
            checked += 1
            flat += bool(np.all(lo == hi))
    assert checked > hr * hr // 2 and flat > hr * hr // 8


@pytest.mark.parametrize("scale", [2, 4])
def test_a_pixel_whose_lr_box_is_one_colour_is_that_colour_whatever_its_history(scale):
    """Where the 3x3 LR neighbourhood of a pixel's nearest sample is one colour (the background around a volume) the
    clamped history and the splat are that colour, so the blend is: the kernel writes it without computing them (a
    region of a colour and a black one, the frame rotating: the clamp on)."""
    n = 10
    rng = np.random.default_rng(5)
    up = TemporalUpsampler(scale)
    up(rng.random((n, n, 3), dtype=np.float32), np.zeros((n, n, 2), np.float32), (0.0, 0.0), rotation=0.0)
    lr = rng.random((n, n, 3), dtype=np.float32)
    lr[:, :4] = (0.2, 0.5, 0.7)
    lr[6:, 6:] = 0.0
    motion = rng.uniform(-1.5, 1.5, (n, n, 2)).astype(np.float32)
    jitter = (-0.3, 0.2)
    out = up(lr, motion, jitter, rng.random((n, n)).astype(np.float32), rotation=2.0)
    ycocg = image_to_ycocg(lr)
    hr = n * scale
    flat = 0
    for y in range(hr):
        ly = min(max(int(np.floor((y + 0.5) / scale - 0.5 - jitter[1] + 0.5)), 0), n - 1)
        for x in range(hr):
            lx = min(max(int(np.floor((x + 0.5) / scale - 0.5 - jitter[0] + 0.5)), 0), n - 1)
            lo, hi = box_minmax(ycocg, lx, ly)
            if np.all(lo == hi):
                np.testing.assert_allclose(out[y, x], lr[ly, lx], atol=1e-6)
                flat += 1
    assert flat > hr * hr // 4


@pytest.mark.parametrize("scale, rotation, settles", [(2, 2.0, True), (2, 0.5, False), (4, 2.0, False), (4, 5.0, True)])
def test_a_flat_pixel_whose_splat_weight_reaches_the_cap_is_made_without_its_history_as_with_it(scale, rotation,
                                                                                                 settles):
    """Where every pixel's splat weight exceeds the history cap (a rotating view at 2x, and at 4x by 5 degrees a frame)
    a flat pixel's new weight is the cap whatever its history holds, and the kernel skips the fetch there (and the
    prepass the motion spread); with the side outputs, which report the history's weight, it fetches it. Both give the
    same image and history, bit for bit, frame after frame, where histories of low weight lie under the flat
    regions (a frame rendered without history first, its pixels then one colour) and where none settles (2x at half
    a degree, 4x at 2 degrees: the cap above the least weight)."""
    from volsr_core.temporal.taau import SETTLING_MARGIN, least_weight

    n = 12
    rng = np.random.default_rng(3)
    settling, fetching = TemporalUpsampler(scale, side_outputs=False), TemporalUpsampler(scale)
    settled = 0
    for t in range(6):
        lr = rng.random((n, n, 3), dtype=np.float32)
        lr[:, : 3 + t] = 0.0  # a black region that grows over what was content: low-weight histories under it
        lr[8:, 8:] = (0.2, 0.5, 0.7)
        motion = rng.uniform(-1.0, 1.0, (n, n, 2)).astype(np.float32)
        depth = rng.random((n, n)).astype(np.float32)
        jitter = halton_jitter(t, jitter_phases(scale))
        images = [up(lr, motion, jitter, depth, rotation=rotation) for up in (settling, fetching)]
        np.testing.assert_array_equal(images[0], images[1])
        np.testing.assert_array_equal(settling.history, fetching.history)
        _, _, sigma, cap, _ = settling._frame_settings(lambda: True, t > 0, rotation, None)
        columns = settling._columns(n, float(jitter[0]), sigma)[0]
        rows = settling._columns(n, float(jitter[1]), sigma)[0]
        settled += least_weight(columns) * least_weight(rows) > cap * SETTLING_MARGIN
    assert settled == (6 if settles else 0), "each case settles every frame (the caps 0.5 and 0.47) or none (1.14, 1)"


@pytest.mark.parametrize("rotation", [0.5, 2.0])
def test_a_flat_pixel_drops_a_history_in_front_of_it_where_the_neighbourhood_shows_parallax(rotation):
    """A frame all one colour (flat everywhere), its depth behind a history nearer by more than the disocclusion
    threshold and its motion vectors spread (parallax): the history is dropped everywhere, so the new weights are
    those of the frame fed without a history; at 2x by half a degree (no pixel settles: the weight is the splat's)
    and by 2 degrees (every pixel settles: the cap)."""
    n, scale = 10, 2
    rng = np.random.default_rng(4)
    up, fresh = TemporalUpsampler(scale, side_outputs=False), TemporalUpsampler(scale, side_outputs=False)
    up(rng.random((n, n, 3), dtype=np.float32), np.zeros((n, n, 2), np.float32), (0.0, 0.0),
       np.full((n, n), 0.1, np.float32), rotation=rotation)
    frame = (np.zeros((n, n, 3), np.float32), rng.uniform(-1.0, 1.0, (n, n, 2)).astype(np.float32), (0.25, -0.25),
             np.full((n, n), 0.9, np.float32))
    up(*frame, rotation=rotation)
    fresh(*frame, rotation=rotation)
    np.testing.assert_array_equal(up.history[..., 3], fresh.history[..., 3])


@pytest.mark.parametrize("scale", [2, 4])
def test_outside_its_background_window_the_estimate_is_the_background_as_taau_writes_it(scale):
    """A frame of a light background with a patch of colours, rotating: outside the window TAAU reports the estimate
    is one colour (the background through YCoCg and back, the box's colour), inside it lies the patch; unknown
    (None) without the background, on a static frame, and before any frame."""
    n, background = 16, (0.76, 0.76, 0.87)
    rng = np.random.default_rng(9)
    up = TemporalUpsampler(scale, side_outputs=False)
    assert up.background_window() is None
    for t in range(3):
        lr = np.empty((n, n, 3), np.float32)
        lr[:] = background
        lr[5:9, 6:11] = rng.random((4, 5, 3))
        motion = rng.uniform(-0.5, 0.5, (n, n, 2)).astype(np.float32)
        out = up(lr, motion, halton_jitter(t, jitter_phases(scale)), rotation=2.0, background=background)
        top, bottom, left, right = up.background_window()
        assert (top, bottom, left, right) == (3 * scale, 11 * scale, 4 * scale, 13 * scale)  # the patch, 2 LR px more
        outside = np.ones(out.shape[:2], bool)
        outside[top:bottom, left:right] = False
        assert np.all(out[outside] == out[0, 0]) and np.abs(out[0, 0] - background).max() < 1e-6
        assert np.any(out[top:bottom, left:right] != out[0, 0])
    up(lr, np.zeros((n, n, 2), np.float32), (0.0, 0.0), rotation=0.0, background=background)
    assert up.background_window() is None, "a static frame: the unclamped blend"
    up(lr, motion, (0.0, 0.0), rotation=2.0)
    assert up.background_window() is None, "no background given"


# -- fine sampling: the bilinear blend and the shorter history -------------------------------------
def test_smoothing_ramps_with_the_output_pixels_per_voxel():
    up = TemporalUpsampler(2)  # smooth between 1.75 and 2.75 output px per voxel
    assert up.smoothing(None) == 0.0
    assert up.smoothing(0.8) == 0.0  # 1.6 output px per voxel
    assert up.smoothing(1.125) == pytest.approx(0.5)  # 2.25
    assert up.smoothing(3.0) == 1.0
    with pytest.raises(ValueError, match="smooth"):
        TemporalUpsampler(2, smooth_between=(2.0, 1.0))


def test_fine_sampling_blends_bilinear_weights_into_the_estimate():
    """A linear ramp, which bilinear interpolation reproduces exactly: fully smoothed (0.75 bilinear),
    the first frame's error is a quarter of the Gaussian splat's."""
    n, scale, jitter = 16, 2, (0.1, -0.2)
    ys, xs = np.mgrid[0:n, 0:n].astype(np.float64)
    ramp = lambda x, y: np.stack([0.2 + 0.01 * x + 0.02 * y] * 3, axis=-1)  # noqa: E731
    lr = ramp(xs + jitter[0], ys + jitter[1]).astype(np.float32)  # samples at their jittered positions
    hr_y, hr_x = np.mgrid[0:n * scale, 0:n * scale].astype(np.float64)
    exact = ramp((hr_x + 0.5) / scale - 0.5, (hr_y + 0.5) / scale - 0.5)
    motion = np.zeros((n, n, 2), dtype=np.float32)
    sharp = TemporalUpsampler(scale)(lr, motion, jitter, rotation=2.0)
    smooth = TemporalUpsampler(scale)(lr, motion, jitter, rotation=2.0, pixels_per_voxel=4.0)
    inner = (slice(4, -4), slice(4, -4))
    err_sharp, err_smooth = sharp[inner] - exact[inner], smooth[inner] - exact[inner]
    assert np.abs(err_sharp).max() > 1e-3, "the Gaussian splat is not exact on a ramp"
    np.testing.assert_allclose(err_smooth, 0.25 * err_sharp, atol=2e-6)


def test_fine_sampling_shortens_the_history_while_the_view_rotates_only():
    scale, n = 2, 8
    lr = np.random.default_rng(3).random((n, n, 3), dtype=np.float32)
    motion = np.full((n, n, 2), 0.01, dtype=np.float32)
    for ppv, cap in ((None, 0.5), (1.125, 0.5 * (1 - 0.75 * 0.5)), (3.0, 0.125)):
        up = TemporalUpsampler(scale)
        for k in range(6):
            up(lr, motion, halton_jitter(k, 32), rotation=2.0, pixels_per_voxel=ppv)
        assert up.history[..., 3].max() == pytest.approx(cap, rel=1e-5)
    still = [TemporalUpsampler(scale) for _ in range(2)]
    for k in range(6):
        a = still[0](lr, motion * 0, halton_jitter(k, 32), rotation=0.0)
        b = still[1](lr, motion * 0, halton_jitter(k, 32), rotation=0.0, pixels_per_voxel=3.0)
        np.testing.assert_array_equal(a, b)  # a still camera converges with the narrow splat, as before


def test_a_finely_sampled_real_volume_is_upscaled_better_with_smoothing(shared_data):
    """The engine in the MR-Angio look (a volume none of TAAU's settings were chosen on), the centre of a
    1024² view (a 256² view zoomed 4x: about 3.6 output px per voxel), 2°/frame: at 2x the smoothing
    TAAU beats the unsmoothed one by over 1 dB on every frame, recovering at least 40% of what that one
    loses to the unjittered bilinear upscale of the same LR size (measured: 59-90%; on this volume
    the smoothed TAAU still stays below bilinear, by 0.4-2.5 dB)."""
    from volsr_core.apps.bench.scenes import load_bench_volume
    from volsr_core.render import RayCaster
    from volsr_core.scene.camera_paths import orbit_around
    from volsr_core.temporal import render_supersampled, upscale_bilinear

    scene = load_bench_volume(str(shared_data / "volumes" / "engine.nii.gz") + ":MR-Angio")
    caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
    cameras = [c.zoom(4.0) for c in orbit_around(caster.visible_bounds(), 10, 2.0)]
    scale, size = 2, 256
    sharp, smooth, scores = TemporalUpsampler(scale), TemporalUpsampler(scale), []
    for i, camera in enumerate(cameras):
        jitter = halton_jitter(i, jitter_phases(scale))
        previous = cameras[i - 1] if i else None
        frame = caster.render(camera, size // scale, jitter=jitter, previous_camera=previous, seed=i)
        rotation = view_rotation(camera, previous)
        a = sharp(frame.color, frame.motion, jitter, frame.motion_depth, rotation)
        b = smooth(frame.color, frame.motion, jitter, frame.motion_depth, rotation, frame.pixels_per_voxel)
        if i >= 6:
            truth = render_supersampled(caster, camera, size, spp=16, seed=1000 + 16 * i)
            centred = caster.render(camera, size // scale, seed=i).color
            scores.append((psnr(b, truth), psnr(a, truth), psnr(upscale_bilinear(centred, scale), truth)))
    print(f"output px per voxel {frame.pixels_per_voxel * scale:.2f}; smooth / sharp / bilinear per frame:",
          np.round(scores, 2).tolist())
    assert frame.pixels_per_voxel * scale > 2.75
    for smoothed, unsmoothed, bilinear in scores:
        assert smoothed > unsmoothed + 1.0
        assert smoothed - unsmoothed > 0.4 * (bilinear - unsmoothed)


@pytest.mark.parametrize("lr_w, scale", [(1, 4), (3, 3), (7, 2), (64, 4), (256, 8)])
def test_the_column_taps_are_their_definition(lr_w, scale):
    """Per HR column the nearest LR sample, the 2x2 window's columns, their Gaussian weights and the fraction past the
    first (HR pixel X at LR position u = (X + 0.5) / scale - 0.5 - jx), and per LR sample the first HR column whose
    nearest sample it is or a later one (numpy's searchsorted), edges clamped."""
    from volsr_core.temporal.taau import _columns

    for jx in (-0.5, -0.125, 0.0, 0.3, 0.49):
        inv2s2 = 1.0 / (2.0 * 0.35 ** 2)
        u = (np.arange(lr_w * scale) + 0.5) / scale - 0.5 - jx
        f = np.floor(u)
        nearest = np.clip(np.floor(u + 0.5), 0, lr_w - 1)
        expected = np.stack([nearest, np.clip(f, 0, lr_w - 1), np.clip(f + 1, 0, lr_w - 1),
                             np.exp(-(u - f) ** 2 * inv2s2), np.exp(-(u - f - 1) ** 2 * inv2s2), u - f], axis=1)
        runs = np.searchsorted(nearest, np.arange(lr_w + 1))
        runs[lr_w] = lr_w * scale
        cols, got_runs = _columns(lr_w * scale, lr_w, scale, jx, inv2s2)
        np.testing.assert_allclose(cols, expected, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got_runs, runs)
