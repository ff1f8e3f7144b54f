"""The PyVista helper: add_sr_volume on a real off-screen (EGL) pv.Plotter."""
from __future__ import annotations

import numpy as np
import pytest

pv = pytest.importorskip("pyvista", reason="PyVista is not installed (pip install 'volsr[pyvista]')")
pytest.importorskip("onnxruntime")

from test_host_vtk import psnr  # noqa: E402

from volsr_core.runtime.pipeline import Pipeline  # noqa: E402
from volsr_core.scene import Volume, get_preset  # noqa: E402

W, H = 128, 96


@pytest.fixture(scope="module")
def volume(ct_avm_path):
    return Volume.load(ct_avm_path)


def test_screenshots_with_a_volsr_preset_are_the_pipelines_output(volume, model):
    from volsr_core.hosts.pyvista import add_sr_volume
    from volsr_core.scene.vtk_bridge import camera_from_vtk

    plotter = pv.Plotter(off_screen=True, window_size=(W, H))
    adapter = add_sr_volume(plotter, volume, transfer_function="CT-AAA", clim=(0, 446), model=model)
    background = tuple(plotter.renderer.GetBackground())  # PyVista's theme colour, the pipeline's background too
    reference = Pipeline(volume, get_preset("CT-AAA").placed_on(0.0, 446.0), model, scale=4, size=(W, H),
                         background=background)
    shot = plotter.screenshot(return_img=True)
    expected = reference.render(camera_from_vtk(plotter.renderer.GetActiveCamera(), W / H))
    value = psnr(shot, expected)
    print(f"PyVista screenshot vs pipeline: {value:.1f} dB")
    assert shot.shape == (H, W, 3) and shot.std() > 5 and value >= 40 and adapter.frames == 1

    plotter.renderer.GetActiveCamera().Azimuth(5)
    plotter.render()
    moved = plotter.screenshot(return_img=True)
    expected = reference.render(camera_from_vtk(plotter.renderer.GetActiveCamera(), W / H))
    value = psnr(moved, expected)
    print(f"after azimuth 5: {value:.1f} dB, vs the first screenshot {psnr(moved, shot):.1f} dB")
    assert value >= 40 and psnr(moved, shot) < 35
    assert adapter.frames == 2 and adapter.pipeline.upscaler.resets == 0

    adapter.enabled = False
    plotter.render()
    assert adapter.vtk_volume.GetVisibility() == 1 and adapter.frames == 2
    plotter.close()


def test_pyvista_colormaps_and_image_data_with_a_direction_matrix(volume, model):
    from volsr_core.hosts.pyvista import add_sr_volume
    from volsr_core.scene.vtk_bridge import camera_from_vtk
    from volsr_core.scene.vtk_bridge import from_vtk_volume_property

    # the image carries its own origin and direction (LPS), no user matrix: VolSR reads them from VTK
    grid = pv.ImageData(dimensions=volume.shape_xyz, spacing=volume.spacing, origin=volume.origin,
                        direction_matrix=volume.direction)
    grid.point_data["CT"] = volume.array.ravel()
    plotter = pv.Plotter(off_screen=True, window_size=(W, H))
    adapter = add_sr_volume(plotter, grid, cmap="bone", opacity="sigmoid", clim=(0, 446), shade=True, model=model)
    tf = from_vtk_volume_property(adapter.vtk_volume.GetProperty())
    assert tf.shade and len(tf.color) > 100  # PyVista's lookup table, read back from the property
    assert np.allclose(adapter.pipeline.caster.volume.index_to_world, volume.index_to_world)
    shot = plotter.screenshot(return_img=True)
    expected = Pipeline(volume, tf, model, scale=4, size=(W, H), background=plotter.renderer.GetBackground()).render(
        camera_from_vtk(plotter.renderer.GetActiveCamera(), W / H))
    value = psnr(shot, expected)
    print(f"PyVista cmap/opacity screenshot vs pipeline: {value:.1f} dB")
    assert value >= 40 and shot.std() > 5
    plotter.close()
