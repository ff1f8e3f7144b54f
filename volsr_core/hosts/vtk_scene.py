"""The same scene drawn by VTK's own volume mappers, offscreen: the reference VolSR is held to.

VTK is imported from ``vtkmodules`` (so Slicer's and ParaView's own VTK serve) and only when
this module is used. Offscreen windows use EGL unless ``VTK_DEFAULT_OPENGL_WINDOW`` says else.
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.scene.vtk_property import to_vtk_volume_property

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonMath import vtkMatrix4x4  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkImageData  # noqa: E402
from vtkmodules.vtkRenderingCore import vtkRenderer, vtkRenderWindow, vtkVolume, vtkWindowToImageFilter  # noqa: E402
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401  (registers the OpenGL window factories)
import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: E402,F401  (registers the volume mapper factories)

MAPPERS = ("gpu", "fixed_point")


def vtk_image(volume: Volume) -> tuple[vtkImageData, vtkMatrix4x4]:
    """The voxels as vtkImageData (spacing only) plus the prop matrix placing them in world LPS.

    Direction and origin go into the vtkVolume's user matrix, which every VTK mapper honours.
    """
    image = vtkImageData()
    image.SetDimensions(*volume.shape_xyz)
    image.SetSpacing(*volume.spacing)
    image.SetOrigin(0.0, 0.0, 0.0)
    scalars = numpy_to_vtk(volume.array.ravel(), deep=True)
    scalars.SetName("scalars")
    image.GetPointData().SetScalars(scalars)
    matrix = vtkMatrix4x4()
    for r in range(3):
        for c in range(3):
            matrix.SetElement(r, c, float(volume.direction[r, c]))
        matrix.SetElement(r, 3, float(volume.origin[r]))
    return image, matrix


def apply_camera(target, camera: Camera) -> None:
    """Copy ``camera`` onto a vtkCamera."""
    target.SetPosition(*camera.position)
    target.SetFocalPoint(*camera.focal_point)
    target.SetViewUp(*camera.view_up)
    target.SetViewAngle(camera.view_angle)
    target.SetParallelProjection(camera.parallel_projection)
    target.SetParallelScale(camera.parallel_scale)
    target.SetClippingRange(*camera.clipping_range)


class VtkVolumeRenderer:
    """An offscreen VTK window showing ``volume`` with ``transfer_function``.

    ``mapper``: "gpu" (vtkGPUVolumeRayCastMapper) or "fixed_point"
    (vtkFixedPointVolumeRayCastMapper, VTK's CPU ray caster). Sampling is fixed at
    ``sample_distance`` mm with no automatic adjustment, no image subsampling and no jitter.
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, width: int, height: int, *,
                 mapper: str = "gpu", sample_distance: float | None = None,
                 background: Sequence[float] = (0.0, 0.0, 0.0)):
        if mapper not in MAPPERS:
            raise ValueError(f"mapper must be one of {MAPPERS}, got {mapper!r}")
        step = float(sample_distance or 0.5 * min(volume.spacing))
        image, matrix = vtk_image(volume)
        if mapper == "gpu":
            from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper as Mapper
        else:
            from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper as Mapper
        self.mapper = Mapper()
        self.mapper.SetInputData(image)
        self.mapper.SetAutoAdjustSampleDistances(False)
        self.mapper.SetSampleDistance(step)
        self.mapper.SetImageSampleDistance(1.0)
        if mapper == "gpu":
            self.mapper.SetUseJittering(False)
        else:
            self.mapper.SetInteractiveSampleDistance(step)
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
        grab = vtkWindowToImageFilter()
        grab.SetInput(self.window)
        grab.SetInputBufferTypeToRGB()
        grab.ReadFrontBufferOff()
        grab.ShouldRerenderOff()
        grab.Update()
        width, height = self.window.GetSize()
        pixels = vtk_to_numpy(grab.GetOutput().GetPointData().GetScalars()).reshape(height, width, -1)
        return (pixels[::-1, :, :3].astype(np.float32) / 255.0).copy()

    def close(self) -> None:
        self.window.Finalize()
