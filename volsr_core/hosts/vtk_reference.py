"""The same scene drawn by VTK's own volume mappers, offscreen: the reference VolSR is held to.

The host's own renderer: the tests compare VolSR's ray caster with it, the renderer benchmarks time
it, and ``volsr bench --vtk`` adds it as a row (what a VTK application would draw at full size). VTK
comes through :mod:`volsr_core._vtk` (``vtkmodules``; offscreen windows use EGL unless
``VTK_DEFAULT_OPENGL_WINDOW`` says else).
"""
from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from volsr_core._vtk import vtkMatrix4x4, vtkRenderer, vtkRenderWindow, vtkVolume
from volsr_core.runtime.methods import Method, MethodFrame
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.scene.vtk_bridge import (
    apply_camera, image_data, placement_matrix, read_window, to_vtk_volume_property, volume_mapper,
)

MAPPERS = ("gpu", "fixed_point")


class VtkVolumeRenderer:
    """An offscreen VTK window showing ``volume`` with ``transfer_function``.

    ``mapper``: "gpu" (vtkGPUVolumeRayCastMapper) or "fixed_point"
    (vtkFixedPointVolumeRayCastMapper, VTK's CPU ray caster). Sampling is fixed at
    ``sample_distance`` mm with no automatic adjustment, no image subsampling and no jitter. The
    voxels are placed by the vtkVolume's user matrix, which every VTK mapper honours.
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, width: int, height: int, *,
                 mapper: str = "gpu", sample_distance: float | None = None,
                 background: Sequence[float] = (0.0, 0.0, 0.0)):
        if mapper not in MAPPERS:
            raise ValueError(f"mapper must be one of {MAPPERS}, got {mapper!r}")
        step = float(sample_distance or 0.5 * min(volume.spacing))
        self.mapper = volume_mapper(mapper)
        self.mapper.SetInputData(image_data(volume, placed=False))
        self.mapper.SetAutoAdjustSampleDistances(False)
        self.mapper.SetSampleDistance(step)
        self.mapper.SetImageSampleDistance(1.0)
        if mapper == "gpu":
            self.mapper.SetUseJittering(False)
        else:
            self.mapper.SetInteractiveSampleDistance(step)
        matrix = vtkMatrix4x4()
        matrix.DeepCopy(placement_matrix(volume).ravel())
        self.actor = vtkVolume()
        self.actor.SetMapper(self.mapper)
        self.actor.SetProperty(to_vtk_volume_property(transfer_function))
        self.actor.SetUserMatrix(matrix)
        self.renderer = vtkRenderer()
        self.renderer.SetBackground(*background)
        self.renderer.AddVolume(self.actor)
        self.window = vtkRenderWindow()
        self.window.SetOffScreenRendering(True)
        self.window.SetSize(width, height)
        self.window.AddRenderer(self.renderer)

    def render(self, camera: Camera) -> np.ndarray:
        """Render and read back (H, W, 3) float32 RGB in [0, 1], row 0 at the top."""
        apply_camera(self.renderer.GetActiveCamera(), camera)
        self.window.Render()
        return read_window(self.window).astype(np.float32) / 255.0

    def close(self) -> None:
        self.window.Finalize()


class VtkMethod(Method):
    """A comparison method (:mod:`volsr_core.runtime.methods`): VTK's own ``mapper`` drawing the volume at
    full size, one Render() and read-back per frame (what a VTK application shows); ``volsr bench --vtk``."""

    kind = "vtk"

    def __init__(self, volume: Volume, transfer_function: TransferFunction, size: tuple[int, int],
                 mapper: str = "gpu", background: Sequence[float] = (0.0, 0.0, 0.0)):
        super().__init__(size)
        self.mapper = mapper
        self.renderer = VtkVolumeRenderer(volume, transfer_function, *self.size, mapper=mapper, background=background)

    @property
    def label(self) -> str:
        return {"gpu": "VTK GPU mapper", "fixed_point": "VTK CPU mapper"}[self.mapper]

    def __call__(self, camera: Camera) -> MethodFrame:
        started = time.perf_counter()
        image = self.renderer.render(camera)
        return MethodFrame(image, 1000.0 * (time.perf_counter() - started))
