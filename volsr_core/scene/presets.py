"""Transfer-function presets: VolSR's own (shipped JSON), our presets files, and Slicer's files.

Our format is JSON: ``{"format": "volsr-presets", "version": 1, "presets": [entry, ...]}`` where
each entry is :meth:`TransferFunction.to_dict`. A file holding one such entry on its own is a
single transfer function. Names are matched case-insensitively. Every bad file gives an
:class:`~volsr_core.errors.InputError`: one line naming the file.
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Mapping
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError, read_text_file
from volsr_core.scene.slicer_presets import read_slicer_presets, read_vp_file
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume

FORMAT = "volsr-presets"
VERSION = 1
_BUILTIN = "volsr-presets.json"


def _decode(text: str, source: str | os.PathLike) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(source, f"not valid JSON: {err.msg} at line {err.lineno} column {err.colno}") from None


def _entry(data: Any, source: str | os.PathLike, label: str) -> TransferFunction:
    """One TransferFunction from a to_dict() entry; ``label`` says which entry in errors."""
    if not isinstance(data, dict):
        raise InputError(source, f"{label} is not a JSON object")
    try:
        return TransferFunction.from_dict(data)
    except (TypeError, ValueError) as err:
        raise InputError(source, f"{label}: {err}") from None


def _presets_from(data: Any, source: str | os.PathLike) -> dict[str, TransferFunction]:
    """The presets of a decoded presets document, by name, in file order."""
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError(source, f"not a VolSR presets file (needs \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise InputError(source, f"presets version {data.get('version')!r} is not supported (only {VERSION})")
    entries = data.get("presets")
    if not isinstance(entries, list):
        raise InputError(source, "\"presets\" is not a list")
    presets: dict[str, TransferFunction] = {}
    for index, entry in enumerate(entries):
        tf = _entry(entry, source, f"preset #{index + 1}")
        if not tf.name:
            raise InputError(source, f"preset #{index + 1} has no name")
        if tf.name.lower() in {n.lower() for n in presets}:
            raise InputError(source, f"preset '{tf.name}' appears twice")
        presets[tf.name] = tf
    return presets



def _pick(presets: Mapping[str, TransferFunction], name: str | None,
          source: str | os.PathLike | None) -> TransferFunction:
    """The preset called ``name`` (any case), or the first when ``name`` is None."""
    if not presets:
        raise InputError(source, "holds no presets")
    if name is None:
        return next(iter(presets.values()))
    for key, tf in presets.items():
        if key.lower() == name.lower():
            return tf
    raise InputError(source, f"no preset '{name}'; available: {', '.join(presets)}")


@lru_cache(maxsize=1)
def _builtin_text() -> str:
    return (files("volsr_core.resources") / "presets" / _BUILTIN).read_text(encoding="utf-8")


def _builtin() -> dict[str, TransferFunction]:
    """VolSR's shipped presets, freshly built (callers may modify them)."""
    return _presets_from(_decode(_builtin_text(), _BUILTIN), _BUILTIN)


def list_presets() -> list[str]:
    """Names of VolSR's shipped presets, in file order."""
    return list(_builtin())


def get_preset(name: str) -> TransferFunction:
    """VolSR's shipped preset ``name`` (case-insensitive); InputError listing the names otherwise.

    CT presets are in HU; MR presets on a normalised 0-1000 range (place them with
    :meth:`TransferFunction.placed_on`). ``metadata`` says which.
    """
    return _pick(_builtin(), name, None)


def load_presets(path: str | os.PathLike) -> dict[str, TransferFunction]:
    """The presets of a VolSR presets JSON file, by name, in file order."""
    return _presets_from(_decode(read_text_file(path), path), path)


def save_presets(path: str | os.PathLike, tfs: Mapping[str, TransferFunction] | Iterable[TransferFunction]) -> None:
    """Write transfer functions as a VolSR presets file, atomically (temp file + os.replace).

    A mapping's keys name the presets; an iterable uses each function's own ``name``.
    """
    items = tfs.items() if isinstance(tfs, Mapping) else ((tf.name, tf) for tf in tfs)
    entries = [{**tf.to_dict(), "name": name} for name, tf in items]
    names = [entry["name"] for entry in entries]
    if not all(names) or len({n.lower() for n in names}) != len(names):
        raise ValueError(f"presets need distinct (case-insensitive), non-empty names; got {names}")
    text = json.dumps({"format": FORMAT, "version": VERSION, "presets": entries}, indent=1) + "\n"
    with atomic_write(path, "w", encoding="utf-8") as out:
        out.write(text)


def _load_json(path: str | os.PathLike, name: str | None) -> TransferFunction:
    data = _decode(read_text_file(path), path)
    if isinstance(data, dict) and "format" not in data:
        tf = _entry(data, path, "transfer function")
        if name is not None and name.lower() != tf.name.lower():
            raise InputError(path, f"holds one transfer function, '{tf.name}', not '{name}'")
        return tf
    return _pick(_presets_from(data, path), name, path)


def _load_vp(path: str | os.PathLike, name: str | None) -> TransferFunction:
    tf = read_vp_file(path)
    if name is not None and name.lower() != tf.name.lower():
        raise InputError(path, f"a .vp file holds one transfer function, '{tf.name}' (its file name), not '{name}'")
    return tf


def load_transfer_function(path: str | os.PathLike, name: str | None = None) -> TransferFunction:
    """One transfer function from a file: ours (JSON), Slicer's ``presets.xml`` or a Slicer ``.vp``.

    ``name`` (any case) picks a preset from a file holding several; the first when None. A file
    holding one function (a single JSON entry, a ``.vp`` named after its file) must match it.
    The kind is told by the suffix (.json, .xml/.mrml, .vp), else by the first character.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in (".json", ".xml", ".mrml", ".vp"):
        head = read_text_file(path).lstrip()[:1]
        suffix = {"{": ".json", "<": ".xml"}.get(head, ".vp")
    if suffix == ".json":
        return _load_json(path, name)
    if suffix == ".vp":
        return _load_vp(path, name)
    return _pick(read_slicer_presets(path), name, path)


def place_on_volume(tf: TransferFunction, volume: Volume, placement: str | tuple[float, float] | None = "auto"
                    ) -> TransferFunction:
    """``tf`` with its design range placed on ``volume``'s values, as ``placement`` says.

    ``None``/"none": unchanged; (lo, hi): the design range mapped onto [lo, hi]; "auto": unchanged
    when the volume is in the preset's units already (HU presets on CT in HU), else the design
    range mapped onto the volume's 0.5-99.5 percentiles (for rescaled CT and MR).
    """
    if placement is None or placement == "none":
        return tf
    if placement == "auto":
        units = tf.metadata.get("units", "HU" if tf.value_range[0] < -500 else "")
        return tf if volume.units and volume.units == units else tf.placed_on(*volume.percentiles())
    low, high = placement
    return tf.placed_on(low, high)


def parse_placement(text: str) -> str | tuple[float, float]:
    """A placement as :func:`place_on_volume` takes it, from its command-line form: "auto", "none" or
    "LO,HI" (finite numbers in the volume's value units, LO < HI); ValueError otherwise."""
    if text in ("auto", "none"):
        return text
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise ValueError(f"range must be auto, none or LO,HI, got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"range needs finite LO and HI, got {text!r}")
    if not hi > lo:
        raise ValueError(f"range needs LO < HI, got {text!r}")
    return lo, hi


def default_preset_name(volume: Volume) -> str:
    """The preset every command uses when none is named: CT-Phantom for VolSR's phantom, CT-Bone otherwise."""
    return "CT-Phantom" if volume.source.startswith("phantom") else "CT-Bone"


def choose_transfer_function(volume: Volume, preset: str | None = None, tf_file: str | os.PathLike | None = None,
                             tf_name: str | None = None,
                             placement: str | tuple[float, float] | None = "auto") -> TransferFunction:
    """The transfer function a command's options ask for, placed on ``volume`` (:func:`place_on_volume`):
    ``tf_file`` (entry ``tf_name``) when given, else the shipped ``preset``, else
    :func:`default_preset_name`."""
    if tf_file is not None:
        tf = load_transfer_function(tf_file, name=tf_name)
    else:
        tf = get_preset(preset or default_preset_name(volume))
    return place_on_volume(tf, volume, placement)
