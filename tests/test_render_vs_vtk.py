"""Against the host: VTK's own vtkGPUVolumeRayCastMapper, offscreen (EGL), same scene and camera."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")

from volsr_core.io import make_phantom  # noqa: E402
from volsr_core.render import RayCaster  # noqa: E402
from volsr_core.scene import Camera, Volume, get_preset  # noqa: E402

W, H = 192, 160


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(np.mean((a - b) ** 2), 1e-12)))


def compare(volume: Volume, tf, direction) -> float:
    from volsr_core.hosts.vtk_reference import VtkVolumeRenderer

    camera = Camera.framing(volume.bounds, direction=direction).zoom(1.5).reset_clipping_range(volume.bounds)
    ours = RayCaster(volume, tf).render(camera, W, H).color
    host = VtkVolumeRenderer(volume, tf, W, H, mapper="gpu")
    theirs = host.render(camera)
    host.close()
    assert theirs.mean() > 0.01 and ours.mean() > 0.01, "both images must show the volume"
    return psnr(ours, theirs)


@pytest.mark.parametrize("scene", ["phantom", "CT_AVM"])
def test_unshaded_render_matches_vtk_gpu_mapper(scene, request):
    if scene == "phantom":
        volume, tf = Volume.from_record(make_phantom()), get_preset("CT-Phantom")
    else:
        volume = Volume.load(request.getfixturevalue("ct_avm_path"))
        tf = get_preset("CT-AAA").placed_on(0.0, 446.0)
    unshaded = replace(tf, shade=False, gradient_opacity=None)
    direction = (0.4, 1.0, -0.3)
    value = compare(volume, unshaded, direction)
    shaded = compare(volume, tf, direction)
    print(f"{scene}: PSNR vs VTK GPU mapper, unshaded {value:.1f} dB, shaded {shaded:.1f} dB")
    assert value >= 30.0
