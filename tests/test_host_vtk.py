"""The VTK host adapter: VolSR as a render post-process of a real offscreen (EGL) VTK window."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")
pytest.importorskip("onnxruntime")

from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.scene import Camera, Volume, get_preset  # noqa: E402

W, H = 128, 96


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 or [0, 1] images (capped at 100 dB for identical ones)."""
    a, b = (np.asarray(x, dtype=np.float64) / (255.0 if x.dtype == np.uint8 else 1.0) for x in (a, b))
    return float(10 * np.log10(1.0 / max(np.mean((a - b) ** 2), 1e-10)))


@pytest.fixture(scope="module")
def ct_avm(ct_avm_path):
    return Volume.load(ct_avm_path), get_preset("CT-AAA").placed_on(0.0, 446.0)


def scene(volume, tf):
    """A plain VTK scene (vtkGPUVolumeRayCastMapper, fixed sampling) looking at the volume from the front."""
    from volsr_core.hosts.vtk_reference import VtkVolumeRenderer
    from volsr_core.scene.vtk_bridge import apply_camera

    host = VtkVolumeRenderer(volume, tf, W, H)
    apply_camera(host.renderer.GetActiveCamera(), Camera.framing(volume.bounds, aspect=W / H).zoom(1.3))
    return host


def test_volsr_frames_in_the_window_are_the_pipelines_and_follow_the_camera(ct_avm, model):
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.images import to_uint8
    from volsr_core.scene.vtk_bridge import camera_from_vtk, read_window

    volume, tf = ct_avm
    host = scene(volume, tf)
    # no Volume given: the adapter builds it from the vtkImageData and the vtkVolume's user matrix
    adapter = VolSRPostProcess(host.renderer, host.actor, None, model)
    reference = Pipeline(volume, tf, model, scale=4, size=(W, H))
    vtk_camera = host.renderer.GetActiveCamera()

    host.window.Render()
    first = read_window(host.window)
    expected = reference.render(camera_from_vtk(vtk_camera, W / H))
    assert host.actor.GetVisibility() == 1, "the host's volume is hidden only while the window renders"
    assert first.shape == (H, W, 3) and first.std() > 5, "the window shows an image, not a blank frame"
    assert psnr(first, np.zeros_like(first)) < 30
    own, pipeline_psnr = psnr(first, to_uint8(adapter.last_image)), psnr(first, expected)
    print(f"frame 1: window vs adapter output {own:.1f} dB, vs a second pipeline {pipeline_psnr:.1f} dB")
    assert own >= 40 and pipeline_psnr >= 40

    vtk_camera.Azimuth(5)
    host.window.Render()
    second = read_window(host.window)
    expected = reference.render(camera_from_vtk(vtk_camera, W / H))
    moved = psnr(second, first)
    following = psnr(second, expected)
    print(f"frame 2 (azimuth 5): vs the pipeline with history {following:.1f} dB, vs frame 1 {moved:.1f} dB")
    assert following >= 40 and moved < 35
    assert adapter.frames == 2 and adapter.pipeline.frame == 2
    assert adapter.pipeline.upscaler.resets == 0 and adapter.resets == 0, "the history was used"
    assert np.abs(adapter.pipeline.last_low_resolution.motion).max() > 0.1
    host.close()


def test_turning_volsr_off_restores_the_hosts_own_rendering(ct_avm, model):
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.images import to_uint8
    from volsr_core.scene.vtk_bridge import camera_from_vtk, read_window

    volume, tf = ct_avm
    host = scene(volume, tf)
    adapter = VolSRPostProcess(host.renderer, host.actor, volume, model)
    host.window.Render()
    volsr = read_window(host.window)

    adapter.enabled = False
    host.window.Render()
    off = read_window(host.window)
    plain = scene(volume, tf)  # the same scene without any adapter
    reference = plain.render(camera_from_vtk(host.renderer.GetActiveCamera(), W / H))
    plain.close()
    value = psnr(off, reference)
    print(f"VolSR off vs plain VTK: {value:.1f} dB (VolSR on vs plain VTK: {psnr(volsr, reference):.1f} dB)")
    assert value >= 40 and host.actor.GetVisibility() == 1
    assert not host.window.GetRenderers().IsItemPresent(adapter.overlay)
    assert adapter.frames == 1

    adapter.enabled = True
    host.window.Render()
    assert psnr(read_window(host.window), to_uint8(adapter.last_image)) >= 40 and adapter.frames == 2
    adapter.detach()
    host.window.Render()
    assert psnr(read_window(host.window), reference) >= 40 and adapter.frames == 2
    host.close()


def test_property_edits_camera_jumps_resizes_and_reentrant_renders(model):
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.images import to_uint8
    from volsr_core.scene.vtk_bridge import read_window
    from volsr_core.scene.vtk_bridge import from_vtk_volume_property

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    host = scene(volume, get_preset("CT-Phantom"))
    adapter = VolSRPostProcess(host.renderer, host.actor, volume, model, reset_angle=30.0)
    host.window.Render()
    host.window.Render()  # nothing changed: no rebuild, no reset
    assert adapter.resets == 0 and adapter.frames == 2

    host.actor.GetProperty().GetScalarOpacity().AddPoint(500.0, 0.9)
    host.window.Render()
    assert adapter.last_reset_reason == "new transfer function"
    now = adapter.pipeline.caster.transfer_function
    assert np.array_equal(now.scalar_opacity, from_vtk_volume_property(host.actor.GetProperty()).scalar_opacity)
    assert [500.0, 0.9] in now.scalar_opacity.tolist()

    host.renderer.GetActiveCamera().Azimuth(60)
    host.window.Render()
    assert adapter.last_reset_reason == "camera turned" and adapter.resets == 2
    host.renderer.GetActiveCamera().Azimuth(5)
    host.window.Render()
    assert adapter.resets == 2

    host.window.SetSize(96, 72)
    host.window.Render()
    assert adapter.last_image.shape == (72, 96, 3) and adapter.last_reset_reason == "new size"
    assert psnr(read_window(host.window), to_uint8(adapter.last_image)) >= 40

    # a render asked for while the adapter is drawing (say, by a progress callback) is ignored
    render = adapter.pipeline.render

    def render_and_ask_again(camera):
        adapter.render()
        host.renderer.Render()  # fires the renderer's StartEvent again: must not recurse
        return render(camera)

    adapter.pipeline.render = render_and_ask_again
    frames = adapter.frames
    host.window.Render()
    assert adapter.frames == frames + 1
    host.close()


def test_a_property_volsr_cannot_hold_leaves_the_frame_to_the_host(model):
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.scene.vtk_bridge import read_window

    volume = Volume.from_record(make_phantom(shape=(40, 40, 40)))
    host = scene(volume, get_preset("CT-Phantom"))
    adapter = VolSRPostProcess(host.renderer, host.actor, volume, model)
    host.actor.GetProperty().GetScalarOpacity().AddPoint(300.0, 0.5, 0.3, 0.0)  # midpoint 0.3: not linear
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        host.window.Render()
    assert "midpoint" in adapter.last_error and adapter.frames == 0
    assert any("host renders the volume itself" in str(w.message) for w in caught)
    assert read_window(host.window).std() > 1, "the host drew the volume"
    host.close()


def test_the_coordinate_rule_vtk_world_is_our_lps_world():
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkRenderingCore import vtkCamera

    from volsr_core.scene.vtk_bridge import apply_camera, camera_from_vtk, image_data, placement_matrix, volume_from_image

    record = make_phantom(shape=(12, 10, 8))
    direction = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    volume = Volume(array=record.array, spacing=(0.7, 0.8, 1.5), origin=(10.0, -20.0, 5.0), direction=direction)
    # placed by the vtkVolume's user matrix (vtk_scene's way) ...
    image = image_data(volume, placed=False)
    placed = volume_from_image(image, placement_matrix(volume))
    # ... or by the image's own origin, spacing and direction, with a non-zero extent start
    own = vtkImageData()
    own.DeepCopy(image)
    own.SetExtent(2, 2 + 7, 0, 9, 0, 11)
    own.SetSpacing(*volume.spacing)
    own.SetDirectionMatrix(*direction.ravel())
    own.SetOrigin(*(np.asarray(volume.origin) - direction @ (np.asarray(volume.spacing) * [2, 0, 0])))
    for built in (placed, volume_from_image(own)):
        assert np.allclose(built.index_to_world, volume.index_to_world)
        assert np.array_equal(built.array, volume.array)

    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.2)).zoom(1.2)
    vtk_camera = vtkCamera()
    apply_camera(vtk_camera, camera)
    back = camera_from_vtk(vtk_camera)
    assert np.allclose(back.view_matrix(), camera.view_matrix()) and back.view_angle == camera.view_angle
    projection = vtk_camera.GetProjectionTransformMatrix(4 / 3, -1, 1)
    assert np.allclose(back.projection_matrix(4 / 3),
                       np.array([[projection.GetElement(r, c) for c in range(4)] for r in range(4)]))
    vtk_camera.UseHorizontalViewAngleOn()
    vtk_camera.SetViewAngle(40.0)
    horizontal = camera_from_vtk(vtk_camera, aspect=2.0)
    assert horizontal.projection_matrix(2.0)[0, 0] == pytest.approx(1 / np.tan(np.radians(20.0)))


def test_without_a_model_the_adapter_draws_with_the_default_volsr_xs_2x(ct_avm):
    """The hosts' default is the model that pays off on a CPU (docs/performance.md): VolSR XS 2x, the frame a
    Pipeline with the same defaults makes."""
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess

    volume, tf = ct_avm
    host = scene(volume, tf)
    adapter = VolSRPostProcess(host.renderer, host.actor, volume)
    assert adapter.pipeline.scale == 2 and adapter.pipeline.engine.path.name == "volsr-XS-2x.onnx"
    assert adapter.pipeline.low_resolution_size == (W // 2, H // 2)
    host.window.Render()
    assert adapter.frames == 1 and adapter.last_error == ""
    expected = Pipeline(volume, tf, size=(W, H)).render(adapter.last_camera)
    assert psnr(adapter.last_image, expected) > 60, "the same model, camera and jitter: the same frame"
    host.close()


def test_xs_at_4x_draws_in_two_depth_slabs_unless_the_host_says_none(ct_avm):
    """At --scale 4 the shipped XS runs on the layered TAAU (two depth slabs) in the host as in a Pipeline with
    the same defaults; ``slabs=0`` gives the TAAU on the frame's colour."""
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess

    volume, tf = ct_avm
    host = scene(volume, tf)
    for slabs, rendered in ((None, 2), (0, 0)):
        adapter = VolSRPostProcess(host.renderer, host.actor, volume, scale=4, slabs=slabs)
        host.window.Render()
        assert adapter.pipeline.slabs == rendered and adapter.last_error == ""
        lr = adapter.pipeline.last_low_resolution
        assert (0 if lr.slabs is None else lr.slabs.shape[0]) == rendered
        expected = Pipeline(volume, tf, scale=4, size=(W, H), slabs=slabs).render(adapter.last_camera)
        assert psnr(adapter.last_image, expected) > 60, "the same model, slabs, camera and jitter: the same frame"
        adapter.detach()
    host.close()


def test_at_4x_a_view_whose_voxels_span_pixels_draws_the_2x_model_at_half_the_viewport_stretched(ct_avm):
    """``stretch="auto"``, the default, at ``scale=4``: zoomed in until a voxel spans two viewport pixels or more, the
    shipped XS 2x on the 1/4-size frame to half the viewport, stretched to it: the frame a Pipeline with ``stretch=2``
    makes; ``stretch=1`` keeps XS 4x."""
    from volsr_core.hosts.vtk_adapter import VolSRPostProcess
    from volsr_core.runtime.pipeline import STRETCH_FROM
    from volsr_core.scene.vtk_bridge import apply_camera

    volume, tf = ct_avm
    host = scene(volume, tf)
    close = Camera.framing(volume.bounds, aspect=W / H).zoom(16.0)
    apply_camera(host.renderer.GetActiveCamera(), close)
    for stretch, model in (("auto", "volsr-XS-2x.onnx"), (1, "volsr-XS-4x.onnx")):
        adapter = VolSRPostProcess(host.renderer, host.actor, volume, scale=4, stretch=stretch)
        host.window.Render()
        assert adapter.frames == 1 and adapter.last_error == "" and adapter.last_image.shape == (H, W, 3)
        assert adapter.pipeline.caster.pixels_per_voxel(adapter.last_camera, H) >= STRETCH_FROM
        assert adapter.pipeline.engine.path.name == model and adapter.pipeline.low_resolution_size == (W // 4, H // 4)
        if stretch == "auto":
            expected = Pipeline(volume, tf, scale=4, stretch=2, size=(W, H)).render(adapter.last_camera)
            assert psnr(adapter.last_image, expected) > 60, "the same model, stretch, camera and jitter: the same frame"
        adapter.detach()
    host.close()
