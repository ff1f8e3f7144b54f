"""3D Slicer volume-rendering presets: ``presets.xml`` (MRML VolumeProperty elements) and ``.vp`` files.

Both store each function as a count followed by flat values: scalar opacity as (value, alpha)
pairs, gradient opacity as (gradient magnitude, alpha) pairs, colour as (value, r, g, b) rows.
Lighting is vtkVolumeProperty's: shade, ambient, diffuse, specular, specular power. A ``.vp``
file holds nine lines, in Slicer's order: interpolation type, shade, diffuse, ambient, specular,
specular power, scalar opacity, gradient opacity, colour; an empty line keeps VTK's default.
Every bad file gives an :class:`~volsr_core.errors.InputError` naming the file (and the preset).
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from volsr_core.errors import InputError
from volsr_core.scene.transfer_function import TransferFunction

_INTERPOLATION = {0: "nearest", 1: "linear"}  # vtkVolumeProperty's VTK_NEAREST / VTK_LINEAR_INTERPOLATION
_VP_LINES = ("interpolation", "shade", "diffuse", "ambient", "specular", "specularPower",
             "scalarOpacity", "gradientOpacity", "colorTransfer")
_LIGHTING = {"ambient": "ambient", "diffuse": "diffuse", "specular": "specular",
             "specularPower": "specular_power"}


def _array(text: str, width: int, where: str) -> np.ndarray:
    """Parse Slicer's "count v0 v1 ..." text into an (n, width) array.

    ``where`` names the function in error messages; problems raise ``ValueError(problem)``.
    """
    tokens = text.split()
    if not tokens:
        raise ValueError(f"{where} is empty")
    try:
        numbers = [float(t) for t in tokens]
    except ValueError:
        raise ValueError(f"{where} holds non-numbers: {text.strip()[:60]!r}") from None
    count, values = numbers[0], numbers[1:]
    if count != int(count) or count < width:
        raise ValueError(f"{where} count {tokens[0]} is not a whole number of at least {width}")
    if int(count) != len(values):
        raise ValueError(f"{where} count says {int(count)} values but {len(values)} follow")
    if len(values) % width:
        raise ValueError(f"{where} has {len(values)} values, not a multiple of {width}")
    return np.asarray(values, dtype=np.float64).reshape(-1, width)


def _number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{where} is not a number: {text.strip()[:40]!r}") from None


def _effective_range(text: str | None) -> list[float] | None:
    """Slicer's advisory ``effectiveRange`` (value units), or None when unset ("0 -1") or malformed."""
    try:
        low, high = (float(t) for t in (text or "").split())
    except ValueError:
        return None
    return [low, high] if low < high else None


def _transfer_function(fields: dict[str, str], name: str, source: str) -> TransferFunction:
    """A TransferFunction from Slicer's attribute strings (missing lighting keeps VTK's defaults)."""
    for key in ("scalarOpacity", "colorTransfer"):
        if not fields.get(key, "").strip():
            raise ValueError(f"lacks {key}")
    kwargs: dict[str, Any] = {
        "name": name,
        "scalar_opacity": _array(fields["scalarOpacity"], 2, "scalarOpacity"),
        "color": _array(fields["colorTransfer"], 4, "colorTransfer"),
    }
    if fields.get("gradientOpacity", "").strip():
        kwargs["gradient_opacity"] = _array(fields["gradientOpacity"], 2, "gradientOpacity")
    if fields.get("shade", "").strip():
        kwargs["shade"] = _number(fields["shade"], "shade") != 0
    for key, field_name in _LIGHTING.items():
        if fields.get(key, "").strip():
            kwargs[field_name] = _number(fields[key], key)
    metadata: dict[str, Any] = {"source": source}
    if fields.get("interpolation", "").strip():
        interpolation = int(_number(fields["interpolation"], "interpolation"))
        metadata["interpolation"] = _INTERPOLATION.get(interpolation, str(interpolation))
    effective = _effective_range(fields.get("effectiveRange"))
    if effective is not None:
        metadata["effective_range"] = effective
    kwargs["metadata"] = metadata
    return TransferFunction(**kwargs)


def read_slicer_presets(path: str | os.PathLike) -> dict[str, TransferFunction]:
    """Every VolumeProperty element of a Slicer ``presets.xml`` (or MRML scene), by its ``name``.

    Values are in the volume's units (HU for the CT presets); ``metadata`` records the source,
    the interpolation type and Slicer's advisory ``effective_range`` where set.
    """
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror or err}") from None
    except ET.ParseError as err:
        raise InputError(path, f"not valid XML: {err}") from None
    elements = list(root.iter("VolumeProperty"))
    if not elements:
        raise InputError(path, "holds no VolumeProperty elements (not a Slicer presets.xml?)")
    presets: dict[str, TransferFunction] = {}
    for index, element in enumerate(elements, start=1):
        name = element.get("name", "").strip()
        if not name:
            raise InputError(path, f"VolumeProperty #{index} has no name")
        if name in presets:
            raise InputError(path, f"preset '{name}' appears twice")
        try:
            presets[name] = _transfer_function(dict(element.attrib), name, "3D Slicer presets.xml")
        except ValueError as err:
            raise InputError(path, f"preset '{name}': {err}") from None
    return presets


def read_vp_file(path: str | os.PathLike) -> TransferFunction:
    """A Slicer ``.vp`` volume-property file; the function is named after the file's stem."""
    name = Path(path).stem
    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(path, f"cannot read as text: {getattr(err, 'strerror', None) or err}") from None
    if len(lines) < len(_VP_LINES):
        raise InputError(path, f"a .vp file has {len(_VP_LINES)} lines ({', '.join(_VP_LINES)}); "
                               f"this one has {len(lines)}")
    try:
        return _transfer_function(dict(zip(_VP_LINES, lines)), name, "3D Slicer .vp")
    except ValueError as err:
        raise InputError(path, f"preset '{name}': {err}") from None
