"""VolSR in ParaView (5.11, pvpython or the GUI's Python shell, builtin session): a view's volume upscaled.

ParaView's world is VTK's, which is VolSR's: LPS millimetres, when the volume is read with VolSR's readers
(:func:`show_volume` hands ParaView our voxels as a vtkImageData with origin, spacing and direction matrix,
through a TrivialProducer). Cameras and transfer functions are read from the view and the volume's display
with the VTK adapter's conversions (:func:`~volsr_core.scene.vtk_bridge.camera_from_vtk`,
:func:`~volsr_core.scene.vtk_bridge.from_vtk_volume_property`), so what VolSR draws is what the view shows:

- colour: the display's lookup table (a vtkColorTransferFunction); opacity: its scalar opacity function;
  shading, ambient, diffuse, specular, specular power and scalar opacity unit distance: the display's;
- ParaView 5.11 has no 1D gradient opacity for volumes, so a preset's gradient opacity is dropped when
  it is put on a display (:func:`apply_transfer_function` says so in its result);
- a lookup table that is not interpolated in RGB or has non-linear nodes (ParaView's own presets) is
  sampled at 256 values into a piecewise-linear RGB one (:func:`transfer_function_of`).

:class:`ViewUpscaler` renders the view, then VolSR with that view's camera and transfer function. It
renders the view before it creates the Pipeline (and its onnxruntime session): in this ParaView, starting
onnxruntime before the first render sometimes aborted the X window.

Needs the builtin session (pvpython, or the GUI without a server connection); ``paraview.simple`` is
imported only when a function here runs. pvpython finds VolSR through a venv (docs/paraview.md,
:mod:`volsr_core.hosts.paraview_venv`).
"""
from __future__ import annotations

import contextlib
import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from volsr_core.runtime.models import DEFAULT_SCALE, default_variant
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume

ARRAY = "scalars"
_SAMPLES = 256  # nodes of a lookup table resampled into piecewise-linear RGB


def simple():
    """``paraview.simple``, imported on first use."""
    from paraview import simple as pvs

    return pvs


# volumes -------------------------------------------------------------------------------------
def volume_source(volume: Volume, registration_name: str = "volume"):
    """A ParaView source (TrivialProducer) producing ``volume`` (builtin session only)."""
    pvs = simple()
    source = pvs.TrivialProducer(registrationName=registration_name)
    from volsr_core.scene.vtk_bridge import image_data

    source.GetClientSideObject().SetOutput(image_data(volume, ARRAY))
    source.UpdatePipeline()
    return source


def _prop_matrix(display) -> np.ndarray | None:
    """The 4x4 matrix the display's Position / Orientation / Scale / Origin make (None when they are unset)."""
    values = [getattr(display, name, None) for name in ("Position", "Orientation", "Scale", "Origin")]
    if any(v is None for v in values):
        return None
    position, orientation, scale, origin = (list(v) for v in values)
    if position == [0.0] * 3 and orientation == [0.0] * 3 and scale == [1.0] * 3:
        return None
    from volsr_core._vtk import vtkVolume
    from volsr_core.scene.vtk_bridge import matrix_4x4

    prop = vtkVolume()  # the same transform maths as the representation's own prop
    prop.SetPosition(*position)
    prop.SetOrientation(*orientation)
    prop.SetScale(*scale)
    prop.SetOrigin(*origin)
    return matrix_4x4(prop.GetMatrix())


def volume_of(source, display=None) -> Volume:
    """Our :class:`Volume` for a ParaView source's vtkImageData output (its array coloured by ``display``, else
    the point scalars), placed by the image's geometry and the display's Position / Orientation / Scale."""
    from volsr_core._vtk import vtkImageData
    from volsr_core.scene.vtk_bridge import volume_from_image

    source.UpdatePipeline()
    image = source.GetClientSideObject().GetOutputDataObject(0)
    if image is None or not image.IsA("vtkImageData"):
        raise ValueError("the source does not produce a vtkImageData (volume rendering needs image data)")
    array = _colour_array(display)
    if array and image.GetPointData().GetArray(array) is not None and \
            image.GetPointData().GetScalars() is not image.GetPointData().GetArray(array):
        copy = vtkImageData()
        copy.ShallowCopy(image)
        copy.GetPointData().SetScalars(image.GetPointData().GetArray(array))
        image = copy
    return volume_from_image(image, None if display is None else _prop_matrix(display), source="<ParaView source>")


def _colour_array(display) -> str:
    if display is None:
        return ""
    try:
        association, name = display.ColorArrayName
    except (AttributeError, ValueError):
        return ""
    return name if association == "POINTS" else ""


# transfer functions ----------------------------------------------------------------------------
def apply_transfer_function(display, tf: TransferFunction, array: str = ARRAY) -> TransferFunction:
    """Show ``display`` as a volume coloured by ``array`` with ``tf``; returns what ParaView now holds
    (``tf`` without gradient opacity: ParaView 5.11 has none for volumes).

    The lookup table and opacity function become ``tf``'s nodes (RGB space, not discretised, never
    rescaled to the data range); lighting, unit distance and linear interpolation go on the display.
    """
    pvs = simple()
    display.SetRepresentationType("Volume")
    pvs.ColorBy(display, ("POINTS", array))
    lut = pvs.GetColorTransferFunction(array)
    pwf = pvs.GetOpacityTransferFunction(array)
    lut.AutomaticRescaleRangeMode = "Never"
    lut.ColorSpace = "RGB"
    lut.Discretize = 0
    lut.UseLogScale = 0
    lut.AllowDuplicateScalars = 1
    lut.RGBPoints = [float(v) for v in np.asarray(tf.color, dtype=np.float64).ravel()]
    lut.ScalarRangeInitialized = 1
    pwf.AllowDuplicateScalars = 1
    pwf.UseLogScale = 0
    pwf.Points = [float(v) for x, a in tf.scalar_opacity for v in (x, a, 0.5, 0.0)]
    pwf.ScalarRangeInitialized = 1
    display.LookupTable = lut
    display.ScalarOpacityFunction = pwf
    display.Shade = int(bool(tf.shade))
    display.Ambient = float(tf.ambient)
    display.Diffuse = float(tf.diffuse)
    display.Specular = float(tf.specular)
    display.SpecularPower = float(tf.specular_power)
    display.ScalarOpacityUnitDistance = float(tf.scalar_opacity_unit_distance)
    display.InterpolationType = "Linear"
    return replace(tf, gradient_opacity=None, metadata=dict(tf.metadata))


def transfer_function_of(display, name: str = "") -> TransferFunction:
    """The transfer function ``display`` draws its volume with, as VolSR holds it.

    Built as a vtkVolumeProperty from the display's lookup table, opacity function and lighting and read
    with :func:`~volsr_core.scene.vtk_bridge.from_vtk_volume_property` (the VTK adapter's conversion). A
    lookup table in another colour space, on a log scale or with non-linear nodes is first sampled at 256
    values into a piecewise-linear RGB one (likewise the opacity function).
    """
    from volsr_core._vtk import vtkVolumeProperty
    from volsr_core.scene.vtk_bridge import from_vtk_volume_property

    lut, pwf = display.LookupTable, display.ScalarOpacityFunction
    if lut is None or pwf is None:
        raise ValueError("the display has no lookup table or opacity function (colour it by a point array)")
    color, opacity = lut.GetClientSideObject(), pwf.GetClientSideObject()
    prop = vtkVolumeProperty()
    prop.SetInterpolationTypeToLinear()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.DisableGradientOpacityOn()
    prop.SetShade(int(display.Shade))
    prop.SetAmbient(float(display.Ambient))
    prop.SetDiffuse(float(display.Diffuse))
    prop.SetSpecular(float(display.Specular))
    prop.SetSpecularPower(float(display.SpecularPower))
    prop.SetScalarOpacityUnitDistance(float(display.ScalarOpacityUnitDistance))
    try:
        if getattr(lut, "UseLogScale", 0):
            raise ValueError("log scale")
        return from_vtk_volume_property(prop, name=name)
    except ValueError:
        prop.SetColor(_resampled_color(color))
        prop.SetScalarOpacity(_resampled_opacity(opacity))
        return from_vtk_volume_property(prop, name=name)


def _resampled_color(function):
    from volsr_core._vtk import vtkColorTransferFunction

    lo, hi = function.GetRange()
    out = vtkColorTransferFunction()
    out.SetColorSpaceToRGB()
    for x in np.linspace(lo, hi, _SAMPLES):
        out.AddRGBPoint(float(x), *function.GetColor(float(x)))
    return out


def _resampled_opacity(function):
    from volsr_core._vtk import vtkPiecewiseFunction

    lo, hi = function.GetRange()
    out = vtkPiecewiseFunction()
    for x in np.linspace(lo, hi, _SAMPLES):
        out.AddPoint(float(x), float(function.GetValue(float(x))))
    return out


# views and cameras ---------------------------------------------------------------------------
def prepare_view(view, size: Sequence[int], background: Sequence[float] = (0.0, 0.0, 0.0)) -> None:
    """``view`` at ``size`` (width, height) with a plain ``background``, no orientation axes and a headlight
    only (VolSR lights with a headlight; ParaView's light kit would light its own rendering differently)."""
    view.ViewSize = [int(size[0]), int(size[1])]
    view.OrientationAxesVisibility = 0
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    if hasattr(view, "BackgroundColorMode"):
        view.BackgroundColorMode = "Single Color"
    view.Background = [float(c) for c in background]
    if hasattr(view, "UseLight") and hasattr(view, "AdditionalLights"):
        view.UseLight = 0  # the light kit off ...
        if any(light.Coords == "Headlight" for light in view.AdditionalLights):
            return
        light = simple().AddLight(view=view)  # ... and one white headlight, as VolSR lights
        light.Coords = "Headlight"
        light.Intensity = 1.0
        light.DiffuseColor = [1.0, 1.0, 1.0]


def set_camera(view, camera: Camera) -> None:
    """Put ``camera`` on ``view`` through its camera properties (ParaView keeps them in sync)."""
    view.CameraPosition = [float(v) for v in camera.position]
    view.CameraFocalPoint = [float(v) for v in camera.focal_point]
    view.CameraViewUp = [float(v) for v in camera.view_up]
    view.CameraViewAngle = float(camera.view_angle)
    view.CameraParallelProjection = int(camera.parallel_projection)
    view.CameraParallelScale = float(camera.parallel_scale)


def view_size(view) -> tuple[int, int]:
    """(width, height) of the view in pixels."""
    w, h = view.ViewSize
    return max(int(w), 1), max(int(h), 1)


def camera_of(view) -> Camera:
    """Our :class:`Camera` for the view's active vtkCamera (clipping range as ParaView's last render set it)."""
    from volsr_core.scene.vtk_bridge import camera_from_vtk

    w, h = view_size(view)
    return camera_from_vtk(view.SMProxy.GetActiveCamera(), aspect=w / h)


def read_view(view) -> np.ndarray:
    """The view's last rendered pixels, uint8 (H, W, 3), row 0 at the top (builtin session)."""
    from volsr_core.scene.vtk_bridge import read_window

    return read_window(view.GetRenderWindow())


# the upscaler --------------------------------------------------------------------------------
class ViewUpscaler:
    """Renders ``view`` and then VolSR with that view's camera and ``display``'s transfer function.

    - ``volume``: our :class:`Volume` of the displayed data; None reads it from ``source``'s output
      (:func:`volume_of`);
    - ``model``, ``scale``, ``variant``, ``device``, ``threads``, ``sample_distance``, ``slabs``, ``stretch``: as
      :class:`~volsr_core.runtime.pipeline.Pipeline` takes them (None model: the shipped one; None slabs:
      the model's own; "auto" stretch, the default: by the view and how fast it turns);
    - the output size is the view's size, the background the view's background colour.

    :meth:`render` returns float32 (H, W, 3) in [0, 1] and keeps ``last_camera``,
    ``last_transfer_function``, ``last_view`` (uint8, ParaView's own frame) and ``pipeline``. The
    Pipeline (and onnxruntime) starts at the first :meth:`render`, after the view's first render.
    A changed transfer function or size drops the history, as the Pipeline does.
    """

    def __init__(self, view, display, source=None, volume: Volume | None = None, model: Any = None, *,
                 scale: int | None = None, variant: str | None = None, device: str = "cpu",
                 threads: int | None = None, sample_distance: float | None = None, slabs: int | None = None,
                 stretch: int | str = "auto"):
        if volume is None and source is None:
            raise ValueError("give the source or the volume")
        self.view, self.display, self.source = view, display, source
        self.volume = volume
        self.options = dict(model=model, scale=scale, variant=variant, device=device, threads=threads,
                            sample_distance=sample_distance, slabs=slabs, stretch=stretch)
        self.pipeline = None
        self.last_camera: Camera | None = None
        self.last_transfer_function: TransferFunction | None = None
        self.last_view: np.ndarray | None = None
        self.last_timings: dict[str, float] = {}

    def render(self) -> np.ndarray:
        """ParaView's frame, then VolSR's: read the view -> :meth:`Pipeline.update` -> :meth:`Pipeline.render`."""
        pvs = simple()
        started = time.perf_counter()
        pvs.Render(self.view)  # ParaView's frame first, always before onnxruntime starts
        self.last_view = read_view(self.view)
        viewed = time.perf_counter()
        camera = camera_of(self.view)
        tf = transfer_function_of(self.display)
        size = view_size(self.view)
        background = tuple(float(c) for c in self.view.Background)
        if self.pipeline is None:
            from volsr_core.runtime.pipeline import Pipeline

            if self.volume is None:
                self.volume = volume_of(self.source, self.display)
            options = dict(self.options)
            model = options.pop("model")
            self.pipeline = Pipeline(self.volume, tf, model, size=size, background=background, **options)
        self.pipeline.update(transfer_function=tf, background=background, size=size)
        image = self.pipeline.render(camera)
        self.last_camera, self.last_transfer_function = camera, tf
        self.last_timings = {"view_ms": 1000 * (viewed - started), **self.pipeline.last_timings}
        return image


# the VolSR Upscale filter's work (volsr_core/hosts/paraview_plugin.py declares the proxy) --------------
class FilterUpscaler:
    """What the "VolSR Upscale" filter does with its properties: a vtkImageData in, an upscaled frame out.

    Set the attributes (the plugin's property setters do), then call :meth:`upscale` with the input
    vtkImageData; it returns float32 (H, W, 3) in [0, 1], row 0 at the top. The Pipeline is kept between
    calls (its history makes the network's output temporally stable) and rebuilt when the model changes,
    or, without a model file, the variant or scale; a new input, transfer function, background or size
    drops the history.

    - ``size`` (width, height); ``model``: a file, which upscales by its own scale, or "" for the
      shipped model of ``variant`` at ``scale`` (by default XS 2x, the model that pays off on a CPU);
    - ``transfer_function_json``: a VolSR transfer function as JSON (``TransferFunction.to_dict``; what
      :func:`sync_filter` copies from a display); "" = ``preset`` placed on ``preset_range`` (LO < HI) or,
      by default, as ``volsr render --range auto`` places it;
    - the camera: ``camera`` keys as :meth:`Camera.to_dict` names them without the clipping range, which
      is fitted to the volume; a position equal to the focal point (the default) = the anterior view
      framing the volume (:meth:`Camera.framing`);
    - ``background``: RGB in [0, 1].
    """

    def __init__(self):
        self.size = (256, 256)
        self.scale = DEFAULT_SCALE
        self.model = ""
        self.variant = default_variant(DEFAULT_SCALE)
        self.preset = "CT-Bone"
        self.preset_range = (0.0, 0.0)
        self.transfer_function_json = ""
        self.camera: dict[str, Any] = {"position": (0.0, 0.0, 0.0), "focal_point": (0.0, 0.0, 0.0),
                                       "view_up": (0.0, 0.0, 1.0), "view_angle": 30.0,
                                       "parallel_projection": False, "parallel_scale": 1.0}
        self.background = (0.0, 0.0, 0.0)
        self.pipeline = None
        self.last_camera: Camera | None = None
        self.last_transfer_function: TransferFunction | None = None
        self._key = None
        self._volume_key = None
        self._volume: Volume | None = None

    def transfer_function(self, volume: Volume) -> TransferFunction:
        from volsr_core.scene.presets import get_preset, place_on_volume

        if self.transfer_function_json.strip():
            return TransferFunction.from_dict(json.loads(self.transfer_function_json))
        lo, hi = (float(v) for v in self.preset_range)
        return place_on_volume(get_preset(self.preset), volume, (lo, hi) if hi > lo else "auto")

    def camera_for(self, volume: Volume) -> Camera:
        w, h = self.size
        c = self.camera
        if np.allclose(np.asarray(c["position"], dtype=float), np.asarray(c["focal_point"], dtype=float)):
            return Camera.framing(volume.bounds, aspect=w / h)
        camera = Camera(position=c["position"], focal_point=c["focal_point"], view_up=c["view_up"],
                        view_angle=float(c["view_angle"]), parallel_projection=bool(c["parallel_projection"]),
                        parallel_scale=float(c["parallel_scale"]))
        return camera.reset_clipping_range(volume.bounds)

    def upscale(self, image) -> np.ndarray:
        """The frame for the input vtkImageData: read the properties -> :meth:`Pipeline.update` -> render."""
        from volsr_core.runtime.pipeline import Pipeline
        from volsr_core.scene.vtk_bridge import volume_from_image

        size = tuple(max(int(v), 1) for v in self.size)
        key = (str(self.model),) if self.model else ("", self.variant, int(self.scale))  # a file: its own scale
        if self._volume_key != (image, image.GetMTime(), _scalars_mtime(image)):
            self._volume = volume_from_image(image, source="<ParaView input>")
            self._volume_key = (image, image.GetMTime(), _scalars_mtime(image))
        tf = self.transfer_function(self._volume)
        background = tuple(float(v) for v in self.background)
        if self.pipeline is None or key != self._key:
            self.pipeline = Pipeline(self._volume, tf, self.model or None, size=size, background=background,
                                     scale=None if self.model else int(self.scale), variant=self.variant)
            self._key = key
        self.pipeline.update(volume=self._volume, transfer_function=tf, background=background, size=size)
        camera = self.camera_for(self._volume)
        result = self.pipeline.render(camera)
        self.last_camera, self.last_transfer_function = camera, tf
        return result


def _scalars_mtime(image) -> int:
    scalars = image.GetPointData().GetScalars()
    return scalars.GetMTime() if scalars is not None else 0


# the pvpython script's job ---------------------------------------------------------------------
def orbit_and_upscale(volume: Volume, tf: TransferFunction, out: str | Path, *, frames: int = 24,
                      degrees: float = 360.0, elevation: float = 0.0, size: Sequence[int] = (512, 512),
                      scale: int | None = None, model: Any = None, variant: str | None = None, device: str = "cpu",
                      threads: int | None = None, video: str | Path | None = None, fps: float = 24.0,
                      save_view: bool = False, side_by_side: bool = False,
                      background: Sequence[float] = (0.0, 0.0, 0.0), log=print) -> dict[str, Any]:
    """Show ``volume`` in a ParaView render view with ``tf``, orbit the camera and upscale every frame.

    Writes to ``out``: ``frame_NNNN.png`` (VolSR), ``paraview_NNNN.png`` (ParaView's own frame, with
    ``save_view``), ``side_by_side_NNNN.png`` (the two, labelled, with ``side_by_side``), ``cameras.json``
    (the cameras read back from the view, a VolSR camera-path file), ``transfer_function.json`` (what the
    display held, VolSR preset JSON), ``summary.json``; and an MP4 at ``video`` when given. Returns the summary.
    """
    from volsr_core.atomic import atomic_write
    from volsr_core.images import mp4_writer, side_by_side as panels_side_by_side, to_uint8, write_png
    from volsr_core.scene.camera_paths import orbit_around, write_camera_path
    from volsr_core.scene.presets import save_presets

    pvs = simple()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    width, height = int(size[0]), int(size[1])
    view = pvs.CreateView("RenderView")
    pvs.SetActiveView(view)
    prepare_view(view, (width, height), background)
    source = volume_source(volume)
    display = pvs.Show(source, view)
    shown = apply_transfer_function(display, tf)
    if tf.gradient_opacity is not None:
        log("note: ParaView 5.11 has no gradient opacity for volumes; it is left out here and in VolSR's frames")
    # ParaView's own first render resets its camera to the bounding-sphere framing: start there
    cameras = orbit_around(volume.bounds, frames, degrees / frames, elevation, aspect=width / height, fill=None)
    upscaler = ViewUpscaler(view, display, volume=volume, model=model, scale=scale, variant=variant,
                            device=device, threads=threads)
    used_cameras, timings = [], []
    with contextlib.ExitStack() as stack:
        writer = stack.enter_context(mp4_writer(video, fps=fps)) if video else None
        for i, camera in enumerate(cameras):
            set_camera(view, camera)
            image = upscaler.render()
            rgb8 = to_uint8(image)
            write_png(out / f"frame_{i:04d}.png", rgb8)
            if save_view:
                write_png(out / f"paraview_{i:04d}.png", upscaler.last_view)
            if side_by_side:
                lw, lh = upscaler.pipeline.low_resolution_size
                panels = [("ParaView 5.11", upscaler.last_view.astype(np.float32) / 255.0),
                          (f"VolSR {upscaler.pipeline.scale}x from {lw}x{lh}", image)]
                write_png(out / f"side_by_side_{i:04d}.png", panels_side_by_side(panels))
            if writer is not None:
                writer.append_data(rgb8)
            used_cameras.append(upscaler.last_camera)
            timings.append(upscaler.last_timings)
            ms = upscaler.last_timings
            log(f"frame {i + 1}/{frames}: ParaView {ms['view_ms']:.0f} ms, VolSR {ms['render_ms']:.0f} ms render + "
                f"{ms['network_ms']:.0f} ms network")
    write_camera_path(out / "cameras.json", used_cameras)
    save_presets(out / "transfer_function.json", [replace(upscaler.last_transfer_function, name=tf.name or "paraview")])
    median = {k: float(np.median([t[k] for t in timings])) for k in timings[0]}
    scale = upscaler.pipeline.scale
    summary = {"frames": frames, "size": [width, height], "scale": scale,
               "low_resolution_size": list(upscaler.pipeline.low_resolution_size),
               "model": str(model) if model is not None else f"shipped {variant or default_variant(scale)} {scale}x",
               "providers": list(upscaler.pipeline.engine.providers), "median_ms": median,
               "gradient_opacity_dropped": tf.gradient_opacity is not None and shown.gradient_opacity is None,
               "video": str(video) if video else None}
    with atomic_write(out / "summary.json", "w", encoding="utf-8") as fh:
        json.dump(summary, fh, indent=1)
        fh.write("\n")
    return summary


def camera_properties(camera: Camera) -> dict[str, Any]:
    """The VolSR Upscale filter's camera properties for ``camera`` (see the plugin)."""
    return {"CameraPosition": [float(v) for v in camera.position],
            "CameraFocalPoint": [float(v) for v in camera.focal_point],
            "CameraViewUp": [float(v) for v in camera.view_up],
            "CameraViewAngle": float(camera.view_angle),
            "CameraParallelProjection": int(camera.parallel_projection),
            "CameraParallelScale": float(camera.parallel_scale)}


def sync_filter(upscale, view, display=None) -> None:
    """Copy ``view``'s camera and size (and ``display``'s transfer function) onto a VolSR Upscale filter proxy."""
    w, h = view_size(view)
    for key, value in camera_properties(camera_of(view)).items():
        setattr(upscale, key, value)
    upscale.Size = [w, h]
    if display is not None:
        upscale.TransferFunction = json.dumps(transfer_function_of(display).to_dict())
