"""The volumes ``volsr bench`` runs on: ``VOLUME[:PRESET[:RANGE]]`` specs, loaded with their placed looks."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from volsr_core.scene.presets import choose_transfer_function, default_preset_name, parse_placement


@dataclass
class BenchVolume:
    """A volume with its transfer function placed on its values; ``label`` names it in reports."""

    name: str
    volume: Any
    transfer_function: Any
    preset: str
    placement: str | tuple[float, float]

    @property
    def label(self) -> str:
        lo, hi = self.transfer_function.value_range
        how = f" ({self.placement})" if isinstance(self.placement, str) else ""
        return f"{self.name}, {self.preset} on {lo:.4g}..{hi:.4g}{how}"


def _is_placement(text: str) -> bool:
    try:
        parse_placement(text)
    except ValueError:
        return False
    return True


def parse_volume_spec(spec: str | None) -> tuple[str | None, str | None, str | tuple[float, float] | None]:
    """``VOLUME[:PRESET[:RANGE]]`` -> (path or None for the phantom, preset or None, range or None).

    RANGE is ``auto``, ``none`` or ``LO,HI``; ``VOLUME:RANGE`` and ``VOLUME::RANGE`` keep the
    default preset. ``phantom`` (or nothing) is the built-in phantom. A spec that names an
    existing file or folder as a whole is taken as a path, colons and all.
    """
    if spec is None or spec == "":
        return None, None, None
    path, preset, placement = spec, None, None
    if not Path(spec).exists() and ":" in spec:
        head, _, last = spec.rpartition(":")
        if _is_placement(last):
            placement = parse_placement(last)
            before, sep, middle = head.rpartition(":")
            if sep and not Path(head).exists():
                path, preset = before, middle or None
            else:
                path = head
        else:
            path, preset = head, last or None
    if path == "" or (path == "phantom" and not Path(path).exists()):
        path = None
    return path, preset, placement


def load_bench_volume(spec: str | None, preset: str | None = None,
                      placement: str | tuple[float, float] = "auto") -> BenchVolume:
    """The volume a spec names (:func:`parse_volume_spec`); ``preset``/``placement`` are the defaults
    for what the spec leaves out (preset: :func:`~volsr_core.scene.presets.default_preset_name`)."""
    from volsr_core.io import make_phantom
    from volsr_core.scene import Volume

    path, own_preset, own_placement = parse_volume_spec(spec)
    if path is None:
        volume, name = Volume.from_record(make_phantom()), "phantom"
    else:
        volume, name = Volume.load(path), Path(path).name
    placement = own_placement if own_placement is not None else placement
    preset = own_preset or preset or default_preset_name(volume)
    tf = choose_transfer_function(volume, preset, placement=placement)
    return BenchVolume(name, volume, tf, tf.name or preset, placement)
