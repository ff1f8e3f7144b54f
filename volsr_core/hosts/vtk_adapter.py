"""VolSR as a render post-process inside VTK: a vtkRenderer's volume drawn by the SR pipeline.

:class:`VolSRPostProcess` attaches to a vtkRenderer that shows a vtkVolume. On every render of
that renderer (its StartEvent) it reads the active vtkCamera and the vtkVolumeProperty, renders
the volume at 1/``scale`` of the viewport with :class:`~volsr_core.runtime.pipeline.Pipeline`,
and shows the upscaled image in an overlay renderer on a higher layer of the same window (a
vtkImageActor filling the viewport). The host's vtkVolume is hidden for that render pass only
(visibility 0 from the renderer's StartEvent to its EndEvent), so VTK does not ray-cast it at
full resolution, while bounds, ResetCamera and picking outside the render still see it.

Coordinates (docs/hosts-vtk.md): VTK's world is VolSR's world, LPS millimetres. A voxel
``(i, j, k)`` of the vtkImageData lies at ``P @ (origin + direction @ (spacing * [i, j, k]))``
with the image's own origin, spacing and direction matrix and ``P`` the vtkVolume's matrix
(position, orientation, scale and user matrix). The :class:`~volsr_core.scene.volume.Volume`
built from them (:func:`~volsr_core.scene.vtk_bridge.volume_from_image`) has exactly that index-to-world map, so VTK's world
coordinates and cameras are taken over unchanged. Scalars are read as (z, y, x) = (k, j, i).
A scene whose world is not LPS (3D Slicer's RAS) passes ``world_matrix``, the rigid map from its
world to LPS, which is applied to the cameras and to a volume read from VTK
(volsr_core/hosts/slicer.py).

VTK comes through :mod:`volsr_core._vtk` and :mod:`volsr_core.scene.vtk_bridge` (``vtkmodules``: Slicer's and
ParaView's VTK serve).
Each render is "read the host -> :meth:`Pipeline.update` -> :meth:`Pipeline.render`"; the pipeline
decides when the history goes. This class keeps only the overlay.
"""
from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from volsr_core._vtk import VTK_UNSIGNED_CHAR, numpy_to_vtk, vtkImageActor, vtkImageData, vtkRenderer
from volsr_core.images import to_uint8
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera import Camera, rigid_matrix, transform_camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.scene.vtk_bridge import (
    camera_from_vtk, from_vtk_volume_property, matrix_4x4, volume_from_image, vtk_volume_input,
)


# the post-process -----------------------------------------------------------------------------
class VolSRPostProcess:
    """Draws ``vtk_volume`` of ``renderer`` with VolSR: render small, upscale, overlay.

    - ``volume``: our :class:`Volume` for the vtkVolume's voxels, in VTK's world; None builds it
      from the mapper's vtkImageData and the vtkVolume's matrix
      (:func:`~volsr_core.scene.vtk_bridge.volume_from_image`), and rebuilds it when either changes;
    - ``model``, ``scale``, ``variant``, ``device``, ``backend``, ``fp16``, ``threads``,
      ``sample_distance``, ``slabs``, ``stretch``: as :class:`~volsr_core.runtime.pipeline.Pipeline` takes them
      (None model: the shipped one of ``variant`` at ``scale`` / ``stretch``, by default VolSR XS 2x, the model
      that pays off on a CPU; a model file upscales by its own scale; None slabs: the model's own (those it was
      trained on: two for the shipped XS 4x and U-Nets), else two depth slabs for XS at 4x and more, XS taking one
      where few pixels show two slabs at once, as an opaque look (``Pipeline``'s slabs by look); ``stretch`` 2
      at ``scale`` 4: the 2x model to half the viewport, stretched bicubically; "auto", the default: so where a voxel
      spans two or more viewport pixels (judged at each new history) or while the view turns fast for its sampling);
    - ``layer``: the window layer of the overlay renderer (default: the host renderer's + 1;
      3D Slicer wants 3); the window gets enough layers;
    - ``reset_angle`` (degrees), ``reset_zoom``: a camera that turned further than this between two
      renders, or zoomed by more than ``reset_zoom`` times, is a cut (the pipeline's ``max_turn`` and
      ``max_zoom``); a changed view angle or projection is one too;
    - ``enabled``: on/off; off shows the host's own rendering again;
    - ``world_matrix``: for a host whose world is not LPS, the rigid 4x4 map from its world to
      VolSR's (3D Slicer: ``diag(-1, -1, 1, 1)``, RAS -> LPS); applied to every camera read from
      VTK and to a volume read from VTK (not to a ``volume`` given here, which is in LPS already).
      None: VTK's world is VolSR's.

    The transfer function is rebuilt from the vtkVolumeProperty (colour, scalar opacity,
    gradient opacity, shading) only when the property or its MTime changed. The pipeline's
    background is the renderer's background colour. The overlay is opaque and covers the host
    renderer's viewport: other props of that renderer are hidden behind it (put them in a
    renderer on a layer above). When a frame cannot be drawn (say a property VolSR cannot hold),
    the host draws it itself, ``last_error`` says why, and a warning is issued once.

    Attributes after a render: ``last_image`` (float32 (H, W, 3), row 0 at the top),
    ``last_camera``, ``frames`` (SR frames drawn), ``resets`` / ``last_reset_reason`` (the
    pipeline's history drops), ``pipeline``.
    """

    def __init__(self, renderer, vtk_volume, volume: Volume | None = None, model: Any = None, *,
                 scale: int | None = None, variant: str | None = None, layer: int | None = None, device: str = "cpu",
                 backend: str = "auto", fp16: bool = False, threads: int | None = None,
                 sample_distance: float | None = None, slabs: int | None = None, stretch: int | str = "auto",
                 reset_angle: float = 30.0, reset_zoom: float = 2.0, enabled: bool = True, world_matrix: Any = None):
        window = renderer.GetRenderWindow()
        if window is None:
            raise ValueError("the renderer is not in a render window yet (add it with window.AddRenderer first)")
        self.renderer, self.vtk_volume, self.window = renderer, vtk_volume, window
        self.world_matrix = None if world_matrix is None else rigid_matrix(world_matrix)
        self._own_volume = volume is None
        self._volume_key = None
        self._property_key = None
        self._transfer_function: TransferFunction | None = None
        if volume is None:
            volume = self._host_volume()
        self.pipeline = Pipeline(volume, self._host_transfer_function(), model, scale=scale,
                                 size=self._viewport_size(), variant=variant, device=device, backend=backend,
                                 fp16=fp16, threads=threads, sample_distance=sample_distance,
                                 background=tuple(renderer.GetBackground()), max_turn=reset_angle,
                                 max_zoom=reset_zoom, slabs=slabs, stretch=stretch)

        self.image = vtkImageData()
        self.image_actor = vtkImageActor()
        self.image_actor.SetInputData(self.image)
        self.image_actor.InterpolateOff()
        self.image_actor.ForceOpaqueOn()
        self.image_actor.GetMapper().BorderOn()  # the quad covers whole pixels, edge ones included
        self.image_actor.GetProperty().SetInterpolationTypeToNearest()
        self.overlay = vtkRenderer()
        self.overlay.SetLayer(renderer.GetLayer() + 1 if layer is None else int(layer))
        self.overlay.InteractiveOff()
        self.overlay.AddViewProp(self.image_actor)
        self.overlay.GetActiveCamera().ParallelProjectionOn()
        if window.GetNumberOfLayers() <= self.overlay.GetLayer():
            window.SetNumberOfLayers(self.overlay.GetLayer() + 1)

        self.last_image: np.ndarray | None = None
        self.last_camera: Camera | None = None
        self.last_error = ""
        self.frames = 0
        self._warned = False
        self._busy = False
        self._hidden = False
        self._enabled = False
        self._observers = [renderer.AddObserver("StartEvent", self._on_start),
                           renderer.AddObserver("EndEvent", self._on_end)]
        self.enabled = enabled

    @property
    def resets(self) -> int:
        """How many times the pipeline dropped the history."""
        return self.pipeline.resets

    @property
    def last_reset_reason(self) -> str:
        return self.pipeline.last_reset_reason

    # switching ---------------------------------------------------------------------------------
    @property
    def enabled(self) -> bool:
        return self._enabled

    @enabled.setter
    def enabled(self, on: bool) -> None:
        on = bool(on)
        if on == self._enabled:
            return
        self._enabled = on
        if on:
            self.window.AddRenderer(self.overlay)
            self.overlay.DrawOff()  # until the first SR frame exists
        else:
            self.window.RemoveRenderer(self.overlay)
            self._restore_volume()
            self.pipeline.reset("switched off")  # frames drawn by the host leave no history
            self.last_camera = None

    def detach(self) -> None:
        """Remove the overlay and the observers; the host draws the volume as before."""
        self.enabled = False
        for tag in self._observers:
            self.renderer.RemoveObserver(tag)
        self._observers = []

    def render(self) -> None:
        """Render the window (does nothing when called from within a render of this adapter)."""
        if not self._busy:
            self.window.Render()

    def set_volume(self, volume: Volume) -> None:
        """Draw ``volume`` (in VolSR's world) from now on instead of what the vtkVolume's mapper reads;
        the history starts afresh."""
        self._own_volume = False
        self.pipeline.update(volume=volume)

    def reset(self, reason: str = "asked") -> None:
        """Drop the history: the next frame starts afresh."""
        self.pipeline.reset(reason)

    # reading the host -------------------------------------------------------------------------
    def _viewport_size(self) -> tuple[int, int]:
        w, h = self.renderer.GetSize()
        return max(int(w), 1), max(int(h), 1)

    def _prop_matrix(self) -> np.ndarray:
        """The vtkVolume's matrix followed by the host-world-to-LPS map."""
        prop = matrix_4x4(self.vtk_volume.GetMatrix())
        return prop if self.world_matrix is None else self.world_matrix @ prop

    def _host_volume(self) -> Volume:
        """The vtkVolume's voxels as a Volume, rebuilt only when its image or matrix changed."""
        image = vtk_volume_input(self.vtk_volume)
        key = (image, image.GetMTime(), tuple(matrix_4x4(self.vtk_volume.GetMatrix()).ravel()))
        if self._volume_key is None or key[0] is not self._volume_key[0] or key[1:] != self._volume_key[1:]:
            self._volume, self._volume_key = volume_from_image(image, self._prop_matrix()), key
        return self._volume

    def _host_transfer_function(self) -> TransferFunction:
        """The vtkVolumeProperty as a TransferFunction, read again only when it or its MTime changed."""
        prop = self.vtk_volume.GetProperty()
        if self._property_key is None or prop is not self._property_key[0] or prop.GetMTime() != self._property_key[1]:
            self._transfer_function = from_vtk_volume_property(prop)
            # keyed after reading: reading creates VTK's default gradient opacity function when none is set
            self._property_key = (prop, prop.GetMTime())
        return self._transfer_function

    def _host_camera(self) -> Camera:
        w, h = self.pipeline.size
        camera = camera_from_vtk(self.renderer.GetActiveCamera(), aspect=w / h)
        return camera if self.world_matrix is None else transform_camera(camera, self.world_matrix)

    # the render hook --------------------------------------------------------------------------
    def _restore_volume(self) -> None:
        if self._hidden:
            self.vtk_volume.SetVisibility(1)
            self._hidden = False

    def _on_end(self, obj=None, event=None) -> None:
        self._restore_volume()

    def _on_start(self, obj=None, event=None) -> None:
        if not self._enabled or self._busy:
            return
        self._busy = True
        try:
            if not self.vtk_volume.GetVisibility():  # hidden by its owner: nothing to draw
                self.overlay.DrawOff()
                return
            self._draw()
            self.overlay.DrawOn()
            self.vtk_volume.SetVisibility(0)
            self._hidden = True
            self.last_error = ""
        except Exception as err:  # the host draws this frame itself
            self.overlay.DrawOff()
            self.last_error = f"{type(err).__name__}: {err}"
            if not self._warned:
                warnings.warn(f"VolSR: the host renders the volume itself ({self.last_error})", RuntimeWarning,
                              stacklevel=2)
                self._warned = True
        finally:
            self._busy = False

    def _draw(self) -> None:
        """Read the host -> update the pipeline -> render -> show."""
        self.pipeline.update(volume=self._host_volume() if self._own_volume else None,
                             transfer_function=self._host_transfer_function(),
                             background=self.renderer.GetBackground(), size=self._viewport_size())
        camera = self._host_camera()
        image = self.pipeline.render(camera)
        self.last_image, self.last_camera = image, camera
        self.frames += 1
        self._show(image)

    def _show(self, image: np.ndarray) -> None:
        h, w = image.shape[:2]
        pixels = np.ascontiguousarray(to_uint8(image)[::-1].reshape(-1, 3))
        scalars = numpy_to_vtk(pixels, deep=True, array_type=VTK_UNSIGNED_CHAR)
        scalars.SetName("volsr")
        if self.image.GetDimensions() != (w, h, 1):
            self.image.SetDimensions(w, h, 1)
        self.image.GetPointData().SetScalars(scalars)
        self.image.Modified()
        self.overlay.SetViewport(*self.renderer.GetViewport())
        camera = self.overlay.GetActiveCamera()  # pixel centres of the image on those of the viewport
        cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
        camera.SetFocalPoint(cx, cy, 0.0)
        camera.SetPosition(cx, cy, 10.0)
        camera.SetViewUp(0.0, 1.0, 0.0)
        camera.SetParallelScale(h / 2.0)
        camera.SetClippingRange(1.0, 100.0)


def attach(renderer, vtk_volume, volume: Volume | None = None, model: Any = None, **options) -> VolSRPostProcess:
    """Shorthand for :class:`VolSRPostProcess` (``options`` as it takes them)."""
    return VolSRPostProcess(renderer, vtk_volume, volume, model, **options)


def transfer_function_of(vtk_volume) -> TransferFunction:
    """The TransferFunction VolSR draws a vtkVolume with (its property, component 0)."""
    return from_vtk_volume_property(vtk_volume.GetProperty())
