"""VTK <-> VolSR conversions, the scene's side of the one VTK boundary (:mod:`volsr_core._vtk` imports VTK).

Conversions, all in VolSR's world (LPS millimetres; docs/conventions.md):

- Volume <-> vtkImageData: :func:`image_data` (placed by the image's own origin, spacing and
  direction matrix, or spacing only plus :func:`placement_matrix` for a vtkVolume's user matrix),
  :func:`volume_from_image` (with the vtkVolume's matrix), :func:`vtk_volume_input`;
- Camera <-> vtkCamera: :func:`camera_from_vtk`, :func:`apply_camera`;
- TransferFunction <-> vtkVolumeProperty: :func:`to_vtk_volume_property`,
  :func:`write_volume_property` (into an existing property, in place), :func:`from_vtk_volume_property`.
  Colour maps to a vtkColorTransferFunction (RGB space), scalar and gradient opacity to
  vtkPiecewiseFunctions, all piecewise linear (midpoint 0.5, sharpness 0), clamped at the ends and
  keeping duplicate values (steps). A function without gradient opacity leaves VTK's default
  (constant 1); reading back, a disabled or constant-1 gradient opacity gives ``None``;
- pixels: :func:`read_window` (a window's last frame as uint8, row 0 at the top).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from volsr_core._vtk import (
    numpy_to_vtk, vtk_to_numpy, vtkColorTransferFunction, vtkFixedPointVolumeRayCastMapper, vtkImageData,
    vtkOpenGLGPUVolumeRayCastMapper, vtkPiecewiseFunction, vtkRenderer, vtkRenderWindow, vtkVolume,
    vtkVolumeProperty, vtkWindowToImageFilter,
)
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume

__all__ = [
    "matrix_4x4", "image_data", "placement_matrix", "image_index_to_world",
    "volume_from_image", "vtk_volume_input", "volume_mapper", "camera_from_vtk", "apply_camera",
    "to_vtk_volume_property", "write_volume_property", "from_vtk_volume_property", "read_window",
]


# matrices ------------------------------------------------------------------------------------------
def matrix_4x4(matrix: Any) -> np.ndarray:
    """A 4x4 float64 array from a vtkMatrix4x4 or anything numpy reads as 4x4."""
    if hasattr(matrix, "GetElement"):
        return np.array([[matrix.GetElement(r, c) for c in range(4)] for r in range(4)], dtype=np.float64)
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"expected a 4x4 matrix, got shape {m.shape}")
    return m


# volumes -------------------------------------------------------------------------------------------
def image_data(volume: Volume, name: str = "scalars", placed: bool = True) -> vtkImageData:
    """The voxels as a vtkImageData, point scalars ``name`` (float32, x fastest as VTK stores them).

    ``placed``: origin, spacing and direction matrix on the image (ParaView and VTK >= 9 readers
    honour them); otherwise spacing only, origin 0, and :func:`placement_matrix` places it as a
    vtkVolume's user matrix (which every VTK volume mapper honours).
    """
    image = vtkImageData()
    image.SetDimensions(*volume.shape_xyz)
    image.SetSpacing(*volume.spacing)
    if placed:
        image.SetOrigin(*volume.origin)
        image.SetDirectionMatrix(*np.asarray(volume.direction, dtype=np.float64).ravel())
    scalars = numpy_to_vtk(np.ascontiguousarray(volume.array, dtype=np.float32).ravel(), deep=True)
    scalars.SetName(name)
    image.GetPointData().SetScalars(scalars)
    return image


def placement_matrix(volume: Volume) -> np.ndarray:
    """4x4: direction and origin, the user matrix that places an unplaced :func:`image_data` in the world."""
    m = np.eye(4)
    m[:3, :3] = volume.direction
    m[:3, 3] = volume.origin
    return m


def image_index_to_world(image: vtkImageData, prop_matrix: np.ndarray | None = None) -> np.ndarray:
    """4x4 map from homogeneous (i, j, k, 1) indices of a vtkImageData to VTK world coordinates.

    Indices count from the image's extent start; ``prop_matrix`` is the vtkVolume's
    ``GetMatrix()`` (identity when None).
    """
    d = image.GetDirectionMatrix()
    direction = np.array([[d.GetElement(r, c) for c in range(3)] for r in range(3)], dtype=np.float64)
    m = np.eye(4)
    m[:3, :3] = direction @ np.diag(image.GetSpacing())
    extent = image.GetExtent()
    m[:3, 3] = np.asarray(image.GetOrigin()) + m[:3, :3] @ np.array(extent[0::2], dtype=np.float64)
    return (np.eye(4) if prop_matrix is None else np.asarray(prop_matrix, dtype=np.float64)) @ m


def volume_from_image(image: vtkImageData, prop_matrix: np.ndarray | None = None, *, modality: str = "OT",
                      units: str = "", source: str = "<vtkImageData>") -> Volume:
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


def vtk_volume_input(vtk_volume: vtkVolume) -> vtkImageData:
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


def volume_mapper(kind: str):
    """A new VTK volume mapper: "gpu" (vtkOpenGLGPUVolumeRayCastMapper) or "fixed_point"
    (vtkFixedPointVolumeRayCastMapper, VTK's CPU ray caster)."""
    if kind == "gpu":
        return vtkOpenGLGPUVolumeRayCastMapper()
    if kind == "fixed_point":
        return vtkFixedPointVolumeRayCastMapper()
    raise ValueError(f"mapper must be 'gpu' or 'fixed_point', got {kind!r}")


# cameras -------------------------------------------------------------------------------------------
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


def apply_camera(target, camera: Camera) -> None:
    """Copy ``camera`` onto a vtkCamera."""
    target.SetPosition(*camera.position)
    target.SetFocalPoint(*camera.focal_point)
    target.SetViewUp(*camera.view_up)
    target.SetViewAngle(camera.view_angle)
    target.SetParallelProjection(camera.parallel_projection)
    target.SetParallelScale(camera.parallel_scale)
    target.SetClippingRange(*camera.clipping_range)


# transfer functions --------------------------------------------------------------------------------
def _fill_piecewise(function: vtkPiecewiseFunction, points: np.ndarray | None) -> vtkPiecewiseFunction:
    function.RemoveAllPoints()
    function.AllowDuplicateScalarsOn()
    function.ClampingOn()
    for x, y in points if points is not None else ((0.0, 1.0), (255.0, 1.0)):  # None: constant 1
        function.AddPoint(float(x), float(y))
    return function


def to_vtk_volume_property(tf: TransferFunction) -> vtkVolumeProperty:
    """A new vtkVolumeProperty with ``tf``'s functions, lighting (component 0), unit distance (mm) and
    linear interpolation (:func:`write_volume_property`)."""
    prop = vtkVolumeProperty()
    write_volume_property(prop, tf)
    return prop


def write_volume_property(prop: vtkVolumeProperty, tf: TransferFunction) -> None:
    """Write ``tf`` into component 0 of ``prop``, editing the functions it holds in place.

    In place, so that an owner (3D Slicer's volume property node and its editors) keeps its function
    objects and sees the change; observers notice it through the property's MTime. A grey colour
    function is replaced by an RGB one. No gradient opacity: a function the property holds becomes
    constant 1; a property without one keeps VTK's default (also constant 1).
    """
    if prop.GetColorChannels(0) == 3:
        color = prop.GetRGBTransferFunction(0)
    else:
        color = vtkColorTransferFunction()
        prop.SetColor(0, color)
    color.RemoveAllPoints()
    color.SetColorSpaceToRGB()
    color.AllowDuplicateScalarsOn()
    color.ClampingOn()
    for x, r, g, b in tf.color:
        color.AddRGBPoint(float(x), float(r), float(g), float(b))
    _fill_piecewise(prop.GetScalarOpacity(0), tf.scalar_opacity)
    if tf.gradient_opacity is not None or prop.HasGradientOpacity(0):  # else VTK's own default stays
        _fill_piecewise(prop.GetGradientOpacity(0), tf.gradient_opacity)
    prop.SetScalarOpacityUnitDistance(0, float(tf.scalar_opacity_unit_distance))
    prop.SetShade(0, int(bool(tf.shade)))
    prop.SetAmbient(0, float(tf.ambient))
    prop.SetDiffuse(0, float(tf.diffuse))
    prop.SetSpecular(0, float(tf.specular))
    prop.SetSpecularPower(0, float(tf.specular_power))
    prop.SetInterpolationTypeToLinear()
    prop.Modified()


def _nodes(function: vtkPiecewiseFunction | vtkColorTransferFunction, width: int, what: str) -> np.ndarray:
    """The (n, width) nodes of a VTK function; ValueError when a segment is not linear."""
    rows = []
    for i in range(function.GetSize()):
        node = [0.0] * (width + 2)
        function.GetNodeValue(i, node)
        midpoint, sharpness = node[width], node[width + 1]
        if midpoint != 0.5 or sharpness != 0.0:
            raise ValueError(f"{what} node {i} has midpoint {midpoint}, sharpness {sharpness}; "
                             "only linear segments (0.5, 0) are supported")
        rows.append(node[:width])
    return np.asarray(rows, dtype=np.float64).reshape(-1, width)


def _gradient_opacity(prop: vtkVolumeProperty) -> np.ndarray | None:
    if prop.GetDisableGradientOpacity():
        return None
    points = _nodes(prop.GetGradientOpacity(0), 2, "gradient opacity")
    return None if np.all(points[:, 1] == 1.0) else points


def _color(prop: vtkVolumeProperty) -> np.ndarray:
    """(n, 4) rows (value, r, g, b); a grey transfer function gives r = g = b."""
    if prop.GetColorChannels(0) == 1:
        grey = _nodes(prop.GetGrayTransferFunction(0), 2, "grey transfer function")
        return grey[:, [0, 1, 1, 1]]
    color = prop.GetRGBTransferFunction(0)
    if color.GetColorSpace() != 0:  # VTK_CTF_RGB
        raise ValueError("colour transfer function is not interpolated in RGB space")
    return _nodes(color, 4, "colour")


def from_vtk_volume_property(prop: vtkVolumeProperty, name: str = "") -> TransferFunction:
    """A TransferFunction from component 0 of a vtkVolumeProperty.

    Raises ValueError when the colour is not interpolated in RGB or a segment is not linear
    (a midpoint or sharpness other than VTK's defaults), which a TransferFunction cannot hold.
    """
    return TransferFunction(
        color=_color(prop),
        scalar_opacity=_nodes(prop.GetScalarOpacity(0), 2, "scalar opacity"),
        gradient_opacity=_gradient_opacity(prop),
        shade=bool(prop.GetShade(0)),
        ambient=prop.GetAmbient(0),
        diffuse=prop.GetDiffuse(0),
        specular=prop.GetSpecular(0),
        specular_power=prop.GetSpecularPower(0),
        scalar_opacity_unit_distance=prop.GetScalarOpacityUnitDistance(0),
        name=name,
    )


# pixels --------------------------------------------------------------------------------------------
def read_window(window: vtkRenderWindow, renderer: vtkRenderer | None = None) -> np.ndarray:
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
    image = grab.GetOutput()
    w, h, _ = image.GetDimensions()
    pixels = vtk_to_numpy(image.GetPointData().GetScalars()).reshape(h, w, -1)
    return pixels[::-1, :, :3].copy()
