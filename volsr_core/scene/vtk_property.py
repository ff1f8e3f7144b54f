"""TransferFunction <-> vtkVolumeProperty (VTK is imported only when these functions run).

Colour maps to a vtkColorTransferFunction (RGB space), scalar and gradient opacity to
vtkPiecewiseFunctions, all piecewise linear (midpoint 0.5, sharpness 0), clamped at the ends
and keeping duplicate values (steps). A function without gradient opacity leaves VTK's default
(constant 1); reading back, a disabled or constant-1 gradient opacity gives ``None``.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from volsr_core.scene.transfer_function import TransferFunction

if TYPE_CHECKING:
    from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
    from vtkmodules.vtkRenderingCore import vtkColorTransferFunction, vtkVolumeProperty


def _piecewise(points: np.ndarray) -> "vtkPiecewiseFunction":
    from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction

    function = vtkPiecewiseFunction()
    function.AllowDuplicateScalarsOn()
    function.ClampingOn()
    for x, y in points:
        function.AddPoint(float(x), float(y))
    return function


def _color_function(points: np.ndarray) -> "vtkColorTransferFunction":
    from vtkmodules.vtkRenderingCore import vtkColorTransferFunction

    function = vtkColorTransferFunction()
    function.AllowDuplicateScalarsOn()
    function.ClampingOn()
    function.SetColorSpaceToRGB()
    for x, r, g, b in points:
        function.AddRGBPoint(float(x), float(r), float(g), float(b))
    return function


def to_vtk_volume_property(tf: TransferFunction) -> "vtkVolumeProperty":
    """A vtkVolumeProperty with ``tf``'s functions, lighting (component 0), unit distance (mm)
    and linear interpolation."""
    from vtkmodules.vtkRenderingCore import vtkVolumeProperty

    prop = vtkVolumeProperty()
    prop.SetInterpolationTypeToLinear()
    prop.SetColor(_color_function(tf.color))
    prop.SetScalarOpacity(_piecewise(tf.scalar_opacity))
    if tf.gradient_opacity is not None:
        prop.SetGradientOpacity(_piecewise(tf.gradient_opacity))
    prop.SetScalarOpacityUnitDistance(float(tf.scalar_opacity_unit_distance))
    prop.SetShade(int(bool(tf.shade)))
    prop.SetAmbient(float(tf.ambient))
    prop.SetDiffuse(float(tf.diffuse))
    prop.SetSpecular(float(tf.specular))
    prop.SetSpecularPower(float(tf.specular_power))
    return prop


def _nodes(function: "vtkPiecewiseFunction | vtkColorTransferFunction", width: int, what: str) -> np.ndarray:
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


def _gradient_opacity(prop: "vtkVolumeProperty") -> np.ndarray | None:
    if prop.GetDisableGradientOpacity():
        return None
    points = _nodes(prop.GetGradientOpacity(0), 2, "gradient opacity")
    return None if np.all(points[:, 1] == 1.0) else points


def _color(prop: "vtkVolumeProperty") -> np.ndarray:
    """(n, 4) rows (value, r, g, b); a grey transfer function gives r = g = b."""
    if prop.GetColorChannels(0) == 1:
        grey = _nodes(prop.GetGrayTransferFunction(0), 2, "grey transfer function")
        return grey[:, [0, 1, 1, 1]]
    color = prop.GetRGBTransferFunction(0)
    if color.GetColorSpace() != 0:  # VTK_CTF_RGB
        raise ValueError("colour transfer function is not interpolated in RGB space")
    return _nodes(color, 4, "colour")


def from_vtk_volume_property(prop: "vtkVolumeProperty", name: str = "") -> TransferFunction:
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
