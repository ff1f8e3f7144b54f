"""ParaView plugin: the "VolSR Upscale" filter (Filters > VolSR), for ParaView 5.11's Python plugins.

Load it in the GUI (Tools > Manage Plugins > Load New, this file) or in pvpython::

    LoadPlugin("/path/to/volsr_core/hosts/paraview_plugin.py", ns=globals())
    upscale = VolSRUpscale(Input=volume_source)   # a source producing vtkImageData
    from volsr_core.hosts.paraview import sync_filter
    Render(view)                                  # ParaView's first render before onnxruntime starts
    sync_filter(upscale, view, display)           # the view's camera and size, the display's transfer function
    image = servermanager.Fetch(upscale)          # vtkImageData, size = Size, point scalars "VolSR"

Input: vtkImageData with point scalars (component 0 is drawn), in world mm (LPS when read with VolSR's
readers). Output: a vtkImageData of Size[0] x Size[1] x 1 pixels, spacing 1, origin 0, point scalars "VolSR":
unsigned char RGB, VTK's row order (row 0 at the bottom), i.e. what a render view would show, rendered by VolSR
at 1/Scale and upscaled. Show it with MapScalars off to see the colours as they are.

Properties: Size, Scale, Model (.onnx, which upscales by its own scale; empty: the shipped model of Variant at
Scale, by default XS 2x, the model that pays off on a CPU: docs/performance.md), Variant, Preset + PresetRange
(LO < HI places the preset's design range there; else automatic placement) or TransferFunction (VolSR JSON,
overrides the preset), the camera (CameraPosition, CameraFocalPoint, CameraViewUp, CameraViewAngle,
CameraParallelProjection, CameraParallelScale; position = focal point: the anterior view framing the volume),
Background. The network keeps its history between updates, so an orbit gets steadier frames.

ParaView 5.11 under Python 3.11 (Debian 12) cannot load any Python plugin until ``inspect.getargspec`` is
put back: run ``import inspect; inspect.getargspec = inspect.getfullargspec`` (or
``volsr_core.hosts.paraview_venv.fix_python_plugins()``) in its Python first.

This file makes VolSR importable first: the package it lies in goes on sys.path and the venv's packages in
front (.venv-paraview or $VOLSR_PARAVIEW_VENV; :mod:`volsr_core.hosts.paraview_venv`, docs/paraview.md).
It must not be named ``paraview.py``: ParaView registers a plugin module under its file's name.
"""
import sys
from pathlib import Path

_PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # the folder holding volsr_core (a repository or site-packages)
if str(_PACKAGE_ROOT) not in sys.path:
    sys.path.append(str(_PACKAGE_ROOT))

from volsr_core.hosts.paraview_venv import activate as _activate, find_venv as _find_venv  # noqa: E402
from volsr_core.hosts.paraview_venv import fix_python_plugins as _fix_python_plugins  # noqa: E402

_VENV = _find_venv(near=_PACKAGE_ROOT)
if _VENV is not None:
    _activate(_VENV)
_fix_python_plugins()

from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy  # noqa: E402
from volsr_core._vtk import VTKPythonAlgorithmBase  # noqa: E402
from volsr_core.runtime.models import DEFAULT_SCALE, default_variant  # noqa: E402

_PRESETS = ("CT-Bone", "CT-AAA", "CT-Cardiac", "CT-Chest-Contrast-Enhanced", "CT-Soft-Tissue", "CT-Lung",
            "CT-Phantom", "MR-Default", "MR-Angio")
_PRESET_DOMAIN = ('<StringListDomain name="list">' + "".join(f'<String value="{p}"/>' for p in _PRESETS)
                  + "</StringListDomain>")


@smproxy.filter(name="VolSRUpscale", label="VolSR Upscale")
@smhint.xml('<ShowInMenu category="VolSR"/>')
@smproperty.input(name="Input", port_index=0)
@smdomain.datatype(dataTypes=["vtkImageData"], composite_data_supported=False)
class VolSRUpscale(VTKPythonAlgorithmBase):
    """Renders the input volume with VolSR at 1/Scale of Size and upscales it: RGB vtkImageData out."""

    def __init__(self):
        VTKPythonAlgorithmBase.__init__(self, nInputPorts=1, nOutputPorts=1, outputType="vtkImageData")
        from volsr_core.hosts.paraview import FilterUpscaler

        self.upscaler = FilterUpscaler()

    # properties ---------------------------------------------------------------------------------
    def _set(self, name, value):
        if getattr(self.upscaler, name) != value:
            setattr(self.upscaler, name, value)
            self.Modified()

    def _set_camera(self, key, value):
        if self.upscaler.camera.get(key) != value:
            self.upscaler.camera[key] = value
            self.Modified()

    @smproperty.intvector(name="Size", default_values=[256, 256])
    @smdomain.intrange(min=1, max=8192)
    def SetSize(self, width, height):
        self._set("size", (int(width), int(height)))

    @smproperty.intvector(name="Scale", default_values=[DEFAULT_SCALE])
    @smdomain.intrange(min=2, max=16)
    def SetScale(self, scale):
        self._set("scale", int(scale))

    @smproperty.stringvector(name="Model", default_values=[""])
    @smdomain.filelist()
    @smhint.filechooser(extensions="onnx", file_description="VolSR ONNX model")
    def SetModel(self, path):
        self._set("model", str(path or ""))

    @smproperty.stringvector(name="Variant", default_values=[default_variant(DEFAULT_SCALE)])
    @smdomain.xml('<StringListDomain name="list"><String value="XS"/><String value="S"/><String value="M"/>'
                  '<String value="L"/></StringListDomain>')
    def SetVariant(self, variant):
        self._set("variant", str(variant))

    @smproperty.stringvector(name="Preset", default_values=["CT-Bone"])
    @smdomain.xml(_PRESET_DOMAIN)
    def SetPreset(self, name):
        self._set("preset", str(name))

    @smproperty.doublevector(name="PresetRange", default_values=[0.0, 0.0])
    def SetPresetRange(self, low, high):
        self._set("preset_range", (float(low), float(high)))

    @smproperty.stringvector(name="TransferFunction", default_values=[""])
    def SetTransferFunction(self, text):
        self._set("transfer_function_json", str(text or ""))

    @smproperty.doublevector(name="CameraPosition", default_values=[0.0, 0.0, 0.0])
    def SetCameraPosition(self, x, y, z):
        self._set_camera("position", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraFocalPoint", default_values=[0.0, 0.0, 0.0])
    def SetCameraFocalPoint(self, x, y, z):
        self._set_camera("focal_point", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraViewUp", default_values=[0.0, 0.0, 1.0])
    def SetCameraViewUp(self, x, y, z):
        self._set_camera("view_up", (float(x), float(y), float(z)))

    @smproperty.doublevector(name="CameraViewAngle", default_values=[30.0])
    def SetCameraViewAngle(self, degrees):
        self._set_camera("view_angle", float(degrees))

    @smproperty.intvector(name="CameraParallelProjection", default_values=[0])
    @smdomain.xml('<BooleanDomain name="bool"/>')
    def SetCameraParallelProjection(self, on):
        self._set_camera("parallel_projection", bool(on))

    @smproperty.doublevector(name="CameraParallelScale", default_values=[1.0])
    def SetCameraParallelScale(self, scale):
        self._set_camera("parallel_scale", float(scale))

    @smproperty.doublevector(name="Background", default_values=[0.0, 0.0, 0.0])
    def SetBackground(self, r, g, b):
        self._set("background", (float(r), float(g), float(b)))

    # the pipeline passes ------------------------------------------------------------------------
    def RequestInformation(self, request, inInfoVec, outInfoVec):
        from volsr_core._vtk import VTK_UNSIGNED_CHAR, vtkDataObject, vtkStreamingDemandDrivenPipeline as sddp

        width, height = (max(int(v), 1) for v in self.upscaler.size)
        info = outInfoVec.GetInformationObject(0)
        info.Set(sddp.WHOLE_EXTENT(), 0, width - 1, 0, height - 1, 0, 0)
        info.Set(vtkDataObject.SPACING(), 1.0, 1.0, 1.0)
        info.Set(vtkDataObject.ORIGIN(), 0.0, 0.0, 0.0)
        vtkDataObject.SetPointDataActiveScalarInfo(info, VTK_UNSIGNED_CHAR, 3)
        return 1

    def RequestUpdateExtent(self, request, inInfoVec, outInfoVec):
        from volsr_core._vtk import vtkStreamingDemandDrivenPipeline as sddp

        info = inInfoVec[0].GetInformationObject(0)  # the whole volume, whatever piece of the frame is asked for
        info.Set(sddp.UPDATE_EXTENT(), info.Get(sddp.WHOLE_EXTENT()), 6)
        return 1

    def RequestData(self, request, inInfoVec, outInfoVec):
        from volsr_core._vtk import VTK_UNSIGNED_CHAR, numpy_to_vtk, vtkImageData
        from volsr_core.images import to_uint8

        volume = vtkImageData.GetData(inInfoVec[0], 0)
        output = vtkImageData.GetData(outInfoVec, 0)
        frame = to_uint8(self.upscaler.upscale(volume))  # (H, W, 3), row 0 at the top
        height, width = frame.shape[:2]
        output.SetExtent(0, width - 1, 0, height - 1, 0, 0)
        output.SetSpacing(1.0, 1.0, 1.0)
        output.SetOrigin(0.0, 0.0, 0.0)
        pixels = numpy_to_vtk(frame[::-1].reshape(-1, 3).copy(), deep=True, array_type=VTK_UNSIGNED_CHAR)
        pixels.SetName("VolSR")
        output.GetPointData().SetScalars(pixels)
        return 1
