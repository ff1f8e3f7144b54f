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
built from them (:func:`volume_from_vtk`) has exactly that index-to-world map, so VTK's world
coordinates and cameras are taken over unchanged. Scalars are read as (z, y, x) = (k, j, i).
A scene whose world is not LPS (3D Slicer's RAS) passes ``world_matrix``, the rigid map from its
world to LPS, which is applied to the cameras and to a volume read from VTK
(volsr_core/hosts/slicer.py).

VTK is imported from ``vtkmodules`` (Slicer's and ParaView's VTK serve) when this module loads.
"""
from __future__ import annotations

import dataclasses
import math
import os
import warnings
from typing import Any

import numpy as np

from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.scene.vtk_property import from_vtk_volume_property

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")

from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonCore import VTK_UNSIGNED_CHAR  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkImageData  # noqa: E402
from vtkmodules.vtkRenderingCore import vtkImageActor, vtkRenderer, vtkWindowToImageFilter  # noqa: E402
import vtkmodules.vtkRenderingOpenGL2  # noqa: E402,F401  (registers the OpenGL window factories)


# conversions ---------------------------------------------------------------------------------
def _matrix(vtk_matrix) -> np.ndarray:
    return np.array([[vtk_matrix.GetElement(r, c) for c in range(4)] for r in range(4)], dtype=np.float64)


def camera_from_vtk(vtk_camera, aspect: float = 1.0) -> Camera:
    """Our :class:`Camera` for a vtkCamera (the same world, no conversion).

    ``aspect`` (viewport width / height) is needed only when the vtkCamera uses a horizontal view
    angle, which becomes the vertical one. A near plane at or behind the position (possible for a
    hand-set parallel camera) is moved just in front of it. Window centre, view shear, off-axis and
    stereo projections are not reproduced.
    """
    view_angle = float(vtk_camera.GetViewAngle())
    if vtk_camera.GetUseHorizontalViewAngle():
        view_angle = math.degrees(2.0 * math.atan(math.tan(math.radians(view_angle) / 2.0) / aspect))
    near, far = vtk_camera.GetClippingRange()
    far = max(float(far), 1e-6)
    near = min(max(float(near), 1e-6 * far), far * (1 - 1e-9))
    return Camera(position=vtk_camera.GetPosition(), focal_point=vtk_camera.GetFocalPoint(),
                  view_up=vtk_camera.GetViewUp(), view_angle=view_angle,
                  parallel_projection=bool(vtk_camera.GetParallelProjection()),
                  parallel_scale=float(vtk_camera.GetParallelScale()), clipping_range=(near, far))


def image_index_to_world(image, prop_matrix: np.ndarray | None = None) -> np.ndarray:
    """4x4 map from homogeneous (i, j, k, 1) indices of a vtkImageData to VTK world coordinates.

    Indices count from the image's extent start; ``prop_matrix`` is the vtkVolume's
    ``GetMatrix()`` (identity when None).
    """
    direction = _matrix_3(image.GetDirectionMatrix())
    m = np.eye(4)
    m[:3, :3] = direction @ np.diag(image.GetSpacing())
    extent = image.GetExtent()
    m[:3, 3] = np.asarray(image.GetOrigin()) + m[:3, :3] @ np.array(extent[0::2], dtype=np.float64)
    return (np.eye(4) if prop_matrix is None else np.asarray(prop_matrix, dtype=np.float64)) @ m


def _matrix_3(vtk_matrix) -> np.ndarray:
    return np.array([[vtk_matrix.GetElement(r, c) for c in range(3)] for r in range(3)], dtype=np.float64)


def volume_from_vtk(image, prop_matrix: np.ndarray | None = None, *, modality: str = "OT", units: str = "",
                    source: str = "<vtkImageData>") -> Volume:
    """A :class:`Volume` from a vtkImageData's point scalars (component 0) and its placement.

    Index-to-world is :func:`image_index_to_world`: spacing = the lengths of its columns, direction
    = the columns normalised (must be orthonormal: a sheared or mirrored-by-scale prop matrix is
    refused like any non-orthonormal direction), origin = its translation.
    """
    scalars = image.GetPointData().GetScalars()
    if scalars is None:
        raise ValueError("the vtkImageData has no point scalars")
    nx, ny, nz = image.GetDimensions()
    values = vtk_to_numpy(scalars)
    if values.ndim == 2:
        values = values[:, 0]
    m = image_index_to_world(image, prop_matrix)
    spacing = np.linalg.norm(m[:3, :3], axis=0)
    return Volume(array=np.asarray(values, dtype=np.float32).reshape(nz, ny, nx), spacing=tuple(spacing),
                  origin=tuple(m[:3, 3]), direction=m[:3, :3] / spacing, modality=modality, units=units,
                  source=source)


def vtk_volume_input(vtk_volume):
    """The vtkImageData a vtkVolume's mapper draws (its pipeline updated first)."""
    mapper = vtk_volume.GetMapper()
    if mapper is None:
        raise ValueError("the vtkVolume has no mapper")
    algorithm = mapper.GetInputAlgorithm()
    if algorithm is not None:
        algorithm.Update()
    image = mapper.GetInput()
    if image is None or not image.IsA("vtkImageData"):
        raise ValueError("the vtkVolume's mapper has no vtkImageData input")
    return image


def to_uint8(image: np.ndarray) -> np.ndarray:
    """float [0, 1] (H, W, 3) -> uint8, rounded: what the overlay shows of a pipeline image."""
    return np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def read_window(window, renderer=None) -> np.ndarray:
    """The window's (or ``renderer``'s viewport's) current pixels as uint8 (H, W, 3), row 0 at the top.

    Reads the back buffer as last rendered, without rendering again.
    """
    grab = vtkWindowToImageFilter()
    grab.SetInput(window)
    grab.SetInputBufferTypeToRGB()
    grab.ReadFrontBufferOff()
    grab.ShouldRerenderOff()
    if renderer is not None:
        grab.SetViewport(*renderer.GetViewport())
    grab.Update()
    out = grab.GetOutput()
    w, h, _ = out.GetDimensions()
    pixels = vtk_to_numpy(out.GetPointData().GetScalars()).reshape(h, w, -1)
    return pixels[::-1, :, :3].copy()


def rigid_matrix(matrix: Any) -> np.ndarray:
    """``matrix`` as a 4x4 float64 array, checked to be a rotation (det +1) plus a translation."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0)):
        raise ValueError(f"expected a 4x4 affine matrix, got shape {m.shape}")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        raise ValueError("the world matrix must be rigid: a rotation (det +1, no mirror, no scale) plus a translation")
    return m


def transform_camera(camera: Camera, matrix: Any) -> Camera:
    """``camera`` carried by the rigid 4x4 ``matrix`` (position, focal point, view up); the image it
    sees of a scene carried by the same matrix is unchanged."""
    m = rigid_matrix(matrix)
    r, t = m[:3, :3], m[:3, 3]
    return dataclasses.replace(camera, position=r @ camera.position + t, focal_point=r @ camera.focal_point + t,
                               view_up=r @ camera.view_up)


def rotation_between(a: Camera, b: Camera) -> float:
    """Angle in degrees of the rotation taking camera ``a``'s (right, up, forward) frame to ``b``'s."""
    ra, rb = np.stack(a.basis()), np.stack(b.basis())
    cos = (np.trace(rb @ ra.T) - 1.0) / 2.0
    return math.degrees(math.acos(float(np.clip(cos, -1.0, 1.0))))


# the post-process -----------------------------------------------------------------------------
class VolSRPostProcess:
    """Draws ``vtk_volume`` of ``renderer`` with VolSR: render small, upscale, overlay.

    - ``volume``: our :class:`Volume` for the vtkVolume's voxels, in VTK's world; None builds it
      from the mapper's vtkImageData and the vtkVolume's matrix (:func:`volume_from_vtk`), and
      rebuilds it when either changes;
    - ``model``, ``scale``, ``variant``, ``device``, ``backend``, ``fp16``, ``threads``,
      ``sample_distance``: as :class:`~volsr_core.runtime.pipeline.Pipeline` takes them (None
      model: the shipped one of ``variant`` at ``scale``);
    - ``layer``: the window layer of the overlay renderer (default: the host renderer's + 1;
      3D Slicer wants 3); the window gets enough layers;
    - ``reset_angle`` (degrees): a camera that turned further than this between two renders,
      a changed view angle, a switched projection or a distance/parallel scale changed by more
      than ``reset_zoom`` times drops the history (the upscaler also drops it by itself on
      implausible motion, a new size, a new transfer function);
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
    ``last_camera``, ``frames`` (SR frames drawn), ``resets`` / ``last_reset_reason`` (history drops
    this adapter asked for), ``pipeline`` (its ``upscaler.resets`` counts every drop).
    """

    def __init__(self, renderer, vtk_volume, volume: Volume | None = None, model: Any = None, *,
                 scale: int = 4, variant: str = "S", layer: int | None = None, device: str = "cpu",
                 backend: str = "auto", fp16: bool = False, threads: int | None = None,
                 sample_distance: float | None = None, reset_angle: float = 30.0, reset_zoom: float = 2.0,
                 enabled: bool = True, world_matrix: Any = None):
        window = renderer.GetRenderWindow()
        if window is None:
            raise ValueError("the renderer is not in a render window yet (add it with window.AddRenderer first)")
        self.renderer, self.vtk_volume, self.window = renderer, vtk_volume, window
        self.reset_angle, self.reset_zoom = float(reset_angle), float(reset_zoom)
        self.world_matrix = None if world_matrix is None else rigid_matrix(world_matrix)
        self._own_volume = volume is None
        self._volume_key = self._geometry_key() if self._own_volume else None
        if volume is None:
            volume = volume_from_vtk(vtk_volume_input(vtk_volume), self._prop_matrix())
        transfer_function = self._read_property()
        self.pipeline = Pipeline(volume, transfer_function, model, scale=scale, size=self._viewport_size(),
                                 variant=variant, device=device, backend=backend, fp16=fp16, threads=threads,
                                 sample_distance=sample_distance, background=tuple(renderer.GetBackground()))

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
        self.resets = 0
        self.last_reset_reason = ""
        self._warned = False
        self._busy = False
        self._hidden = False
        self._enabled = False
        self._observers = [renderer.AddObserver("StartEvent", self._on_start),
                           renderer.AddObserver("EndEvent", self._on_end)]
        self.enabled = enabled

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
            self.pipeline.reset()  # frames drawn by the host leave no history
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
        self.pipeline.set_volume(volume)
        self._own_volume, self._volume_key = False, None
        self.reset("new volume")

    def reset(self, reason: str = "asked") -> None:
        """Drop the history: the next frame starts afresh."""
        self.pipeline.reset()
        self.resets += 1
        self.last_reset_reason = reason

    # the render hook --------------------------------------------------------------------------
    def _viewport_size(self) -> tuple[int, int]:
        w, h = self.renderer.GetSize()
        return max(int(w), 1), max(int(h), 1)

    def _prop_matrix(self) -> np.ndarray:
        """The vtkVolume's matrix followed by the host-world-to-LPS map."""
        prop = _matrix(self.vtk_volume.GetMatrix())
        return prop if self.world_matrix is None else self.world_matrix @ prop

    def _geometry_key(self):
        image = vtk_volume_input(self.vtk_volume)
        return image, image.GetMTime(), tuple(_matrix(self.vtk_volume.GetMatrix()).ravel())

    def _read_property(self) -> TransferFunction:
        prop = self.vtk_volume.GetProperty()
        tf = from_vtk_volume_property(prop)
        # keyed after reading: reading creates VTK's default gradient opacity function when none is set
        self._property_key = (prop, prop.GetMTime())
        return tf

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

    def _sync_scene(self) -> None:
        """Follow the host: geometry, transfer function, background, viewport size."""
        if self._own_volume:
            key = self._geometry_key()
            if key[0] is not self._volume_key[0] or key[1:] != self._volume_key[1:]:
                self.pipeline.set_volume(volume_from_vtk(key[0], self._prop_matrix()))
                self._volume_key = key
                self.reset("new volume")
        prop = self.vtk_volume.GetProperty()
        if prop is not self._property_key[0] or prop.GetMTime() != self._property_key[1]:
            self.pipeline.set_transfer_function(self._read_property())
            self.last_camera = None
            self.resets += 1
            self.last_reset_reason = "new transfer function"
        background = tuple(float(c) for c in self.renderer.GetBackground())
        if self.pipeline.set_background(background):
            self.reset("new background")
        size = self._viewport_size()
        if size != self.pipeline.size:
            self.pipeline.resize(*size)
            self.reset("new size")

    def _camera_jump(self, camera: Camera) -> str:
        last = self.last_camera
        if last is None:
            return ""
        if last.parallel_projection != camera.parallel_projection:
            return "projection switched"
        if not camera.parallel_projection and abs(camera.view_angle - last.view_angle) > 1e-9:
            return "view angle changed"
        if rotation_between(last, camera) > self.reset_angle:
            return "camera turned"
        ratio = (camera.parallel_scale / last.parallel_scale if camera.parallel_projection
                 else camera.distance / last.distance)
        if max(ratio, 1.0 / ratio) > self.reset_zoom:
            return "zoom jump"
        return ""

    def _draw(self) -> None:
        self._sync_scene()
        w, h = self.pipeline.size
        camera = camera_from_vtk(self.renderer.GetActiveCamera(), aspect=w / h)
        if self.world_matrix is not None:
            camera = transform_camera(camera, self.world_matrix)
        reason = self._camera_jump(camera)
        if reason:
            self.reset(reason)
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
