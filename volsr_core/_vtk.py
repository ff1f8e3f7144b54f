"""VolSR's one door to VTK: every ``vtkmodules`` import of volsr_core is here, as PyVista's ``plotting/_vtk.py``.

Importing it imports what VolSR uses of VTK (from ``vtkmodules``, so 3D Slicer's and ParaView's own VTK
serve; never a pip-only path) and, outside 3D Slicer and ParaView, makes EGL the default offscreen window
(``VTK_DEFAULT_OPENGL_WINDOW``, unless already set) once. Inside a host application the host's window
class stays. The core imports without VTK: only the .vti reader, the VTK conversions
(:mod:`volsr_core.scene.vtk_bridge`), hosts, benchmarks and tests import this module, and only when used.
"""
from __future__ import annotations

import os
import sys

if not any(host in sys.modules for host in ("slicer", "paraview")):
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402
from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase  # noqa: E402
from vtkmodules.vtkCommonCore import (  # noqa: E402
    VTK_UNSIGNED_CHAR, vtkLogger, vtkOutputWindow, vtkStringOutputWindow,
)
from vtkmodules.vtkCommonDataModel import vtkDataObject, vtkImageData, vtkPiecewiseFunction  # noqa: E402
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline  # noqa: E402
from vtkmodules.vtkCommonMath import vtkMatrix4x4  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLImageDataReader  # noqa: E402
from vtkmodules.vtkRenderingCore import (  # noqa: E402
    vtkCamera, vtkColorTransferFunction, vtkImageActor, vtkRenderer, vtkRenderWindow, vtkVolume, vtkVolumeProperty,
    vtkWindowToImageFilter,
)
from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper  # noqa: E402
from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper  # noqa: E402
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401  (registers the OpenGL window factories)

__all__ = [
    "VTKPythonAlgorithmBase", "VTK_UNSIGNED_CHAR", "numpy_to_vtk", "vtk_to_numpy", "vtkCamera",
    "vtkColorTransferFunction", "vtkDataObject", "vtkFixedPointVolumeRayCastMapper", "vtkImageActor", "vtkImageData",
    "vtkLogger", "vtkMatrix4x4", "vtkOpenGLGPUVolumeRayCastMapper", "vtkOutputWindow", "vtkPiecewiseFunction",
    "vtkRenderWindow", "vtkRenderer", "vtkStreamingDemandDrivenPipeline", "vtkStringOutputWindow", "vtkVolume",
    "vtkVolumeProperty", "vtkWindowToImageFilter", "vtkXMLImageDataReader",
]
