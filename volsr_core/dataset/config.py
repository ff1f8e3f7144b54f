"""Dataset configs (YAML): what ``volsr dataset`` renders. See docs/dataset.md for the layout.

A config names the image sizes, the scales, the frames per video, the ground truth, the camera
motion and the volumes with their transfer functions and video counts. :func:`read_config`
reads the file into the sections below (:mod:`volsr_core.config_reader`), checks what they
cannot say (paths, scales, ranges, names) and raises a one-line :class:`InputError`
``"<config>: <key>: <problem>"``.
Volume and transfer-function paths are relative to the config file's folder; ``phantom`` names
VolSR's synthetic CT (``phantom_shape`` (z, y, x) voxels, default 128^3).
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Literal, get_args

from volsr_core.config_reader import fail, read_dataclass, read_value, read_yaml, setting
from volsr_core.dataset.store import VERSION as STORE_VERSION
from volsr_core.errors import InputError
from volsr_core.scene.presets import get_preset, load_transfer_function

SCALES = (2, 4, 8, 16)
GroundTruthMode = Literal["supersampled", "taa"]
PHANTOM = "phantom"
PHANTOM_SHAPE = (128, 128, 128)
Split = Literal["train", "val", "test"]
SPLITS: tuple[str, ...] = get_args(Split)
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
POOL_KEYS = ("pool_size", "view_angle", "distance_range", "max_roll", "focal_jitter")  # the rest: the path's


@dataclass(frozen=True)
class VolumeSpec:
    """One ``volumes`` entry. ``source`` is the resolved file or folder (None for the phantom);
    ``transfer_function`` holds ``preset`` or ``file`` (resolved) + ``name``, and ``range``
    (None, ``"auto"`` or [lo, hi]); ``tf_definition`` is that function as loaded
    (:meth:`TransferFunction.to_dict`, before it is placed on a range). ``split`` puts every
    video of the volume in one split (a held-out volume); None cuts them 80/10/10."""

    name: str
    path: str
    source: Path | None
    phantom_shape: tuple[int, int, int] | None
    transfer_function: dict[str, Any]
    tf_definition: dict[str, Any]
    videos: int
    split: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The entry as read, paths resolved (absolute)."""
        d: dict[str, Any] = {"name": self.name, "path": str(self.source) if self.source else PHANTOM}
        if self.phantom_shape is not None:
            d["phantom_shape"] = list(self.phantom_shape)
        d = {**d, "transfer_function": dict(self.transfer_function), "videos": self.videos}
        return {**d, "split": self.split} if self.split else d


@dataclass(frozen=True)
class DatasetConfig:
    """A checked dataset config. ``hr_size`` is (width, height) in pixels; ``pool`` holds
    :func:`candidate_pool`'s arguments (``pool_size`` = its ``n``), ``path`` those of
    :func:`smooth_random_path` (degrees, degrees per frame, zoom factors)."""

    file: Path
    seed: int
    hr_size: tuple[int, int]
    scales: tuple[int, ...]
    frames_per_video: int
    previous_frames: int
    ground_truth: dict[str, Any]
    pool: dict[str, Any]
    path: dict[str, Any]
    volumes: tuple[VolumeSpec, ...]
    slabs: int = 0  # LR frames also cut into this many depth slabs (RayCaster.render(..., slabs=K)); 0: none

    def to_dict(self) -> dict[str, Any]:
        """The config as read, defaults filled in and paths resolved (the manifest's ``config``)."""
        return {"seed": self.seed, "hr_size": list(self.hr_size), "scales": list(self.scales),
                "frames_per_video": self.frames_per_video, "previous_frames": self.previous_frames,
                "ground_truth": dict(self.ground_truth), "camera": {**self.pool, **self.path},
                "volumes": [v.to_dict() for v in self.volumes], "slabs": self.slabs}

    def fingerprint(self, volume_index: int, video_index: int) -> str:
        """SHA-256 of everything that decides one video's store: the common settings, its volume's
        entry (the volume path as written, the transfer function's content and range; not
        ``videos``) and its place. So a dataset resumes from another checkout or machine, and an
        edited transfer function or preset makes its videos stale."""
        spec = self.volumes[volume_index]
        key = {"seed": self.seed, "hr_size": self.hr_size, "scales": self.scales, "frames": self.frames_per_video,
               "ground_truth": self.ground_truth, "camera": {**self.pool, **self.path},
               "volume": {"name": spec.name, "path": spec.path, "phantom_shape": spec.phantom_shape,
                          "transfer_function": spec.tf_definition, "range": spec.transfer_function["range"]},
               "volume_index": volume_index, "video_index": video_index, "store_version": STORE_VERSION}
        if self.slabs:  # only where set, so that the videos of datasets made before slabs existed stay current
            key["slabs"] = self.slabs
        return "sha256:" + hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


# -- the file's sections, as written (read_config turns them into a DatasetConfig) ----------------
@dataclass(frozen=True, kw_only=True)
class _GroundTruth:
    """How the HR frames are made: supersampled at ``spp`` rays per pixel, or TAA."""

    mode: GroundTruthMode = "supersampled"
    spp: int = setting(16, low=1)


@dataclass(frozen=True, kw_only=True)
class _Camera:
    """candidate_pool's arguments (``pool_size`` is its ``n``), then smooth_random_path's."""

    pool_size: int = setting(64, low=1)
    view_angle: float = setting(30.0, low=1.0, high=179.0)
    distance_range: tuple[float, float] = setting((0.9, 1.6), low=0.01, expected="[low, high]")
    max_roll: float = setting(20.0, low=0.0, high=180.0)
    focal_jitter: float = setting(0.05, low=0.0, high=1.0)
    max_orbit_speed: float = setting(3.0, low=0.0, high=90.0)
    min_orbit_speed: float | None = setting(None, low=0.01, high=90.0)  # set: each video's top speed is drawn
    # log-uniformly from [min_orbit_speed, max_orbit_speed] (slow drags and fast turns in one dataset)
    max_elevation_speed: float = setting(1.5, low=0.0, high=90.0)
    zoom_range: tuple[float, float] = setting((0.8, 1.5), low=0.01, expected="[low, high]")
    max_elevation: float = setting(60.0, low=0.1, high=89.9)
    max_zoom_speed: float = setting(0.01, low=0.0, high=1.0)
    period: int = setting(30, low=1)


@dataclass(frozen=True, kw_only=True)
class _TransferFunctionEntry:
    """``{preset, range?}`` or ``{file, name?, range?}``; ``range`` is None, ``"auto"`` or [lo, hi]."""

    preset: str | None = None
    file: str | None = None
    name: str | None = None
    range: Any = None


@dataclass(frozen=True, kw_only=True)
class _VolumeEntry:
    """One ``volumes`` entry as written (see :class:`VolumeSpec`)."""

    name: str
    path: str
    phantom_shape: tuple[int, int, int] | None = setting(None, low=8, expected="[z, y, x] voxels")
    transfer_function: _TransferFunctionEntry
    videos: int = setting(low=1)
    split: Split | None = None


@dataclass(frozen=True, kw_only=True)
class _Document:
    """The whole file as written."""

    seed: int = setting(low=0)
    hr_size: Any  # an integer or [width, height]
    scales: tuple[int, ...]
    frames_per_video: int = setting(low=1)
    previous_frames: int = setting(low=0)
    ground_truth: _GroundTruth
    camera: _Camera
    volumes: tuple[_VolumeEntry, ...]
    slabs: int = setting(0, low=0, high=8)


def read_config(path: str | os.PathLike) -> DatasetConfig:
    """Read and check a dataset config (YAML); InputError ``"<path>: <key>: <problem>"`` otherwise."""
    file = Path(path)
    doc = read_dataclass(_Document, read_yaml(file), file)
    scales = _scales(file, doc.scales)
    if doc.frames_per_video <= doc.previous_frames:
        fail(file, "frames_per_video",
             f"must exceed previous_frames ({doc.previous_frames}), got {doc.frames_per_video}")
    pool, motion = _camera(file, doc.camera)
    return DatasetConfig(file=file.resolve(), seed=doc.seed, hr_size=_hr_size(file, doc.hr_size, scales),
                         scales=scales, frames_per_video=doc.frames_per_video, previous_frames=doc.previous_frames,
                         ground_truth=asdict(doc.ground_truth), pool=pool, path=motion,
                         volumes=_volumes(file, doc.volumes), slabs=doc.slabs)


def _scales(file: Path, scales: tuple[int, ...]) -> tuple[int, ...]:
    if not scales:
        fail(file, "scales", f"expected a non-empty list of {SCALES}, got []")
    bad = [s for s in scales if s not in SCALES]
    if bad:
        fail(file, "scales", f"{bad[0]} is not one of {', '.join(map(str, SCALES))}")
    if len(set(scales)) != len(scales):
        fail(file, "scales", f"repeats a scale: {list(scales)}")
    return tuple(sorted(scales))


def _hr_size(file: Path, value: Any, scales: tuple[int, ...]) -> tuple[int, int]:
    if isinstance(value, list):
        if len(value) != 2:
            fail(file, "hr_size", f"expected an integer or [width, height], got {value!r}")
        width, height = (read_value(int, v, file, "hr_size", low=1) for v in value)
    else:
        width = height = read_value(int, value, file, "hr_size", low=1)
    for s in scales:
        if width % s or height % s:
            fail(file, "hr_size", f"{width}x{height} is not divisible by scale {s}")
    return width, height


def _camera(file: Path, camera: _Camera) -> tuple[dict[str, Any], dict[str, Any]]:
    """candidate_pool's and smooth_random_path's arguments ([low, high] pairs as lists)."""
    for key in ("distance_range", "zoom_range"):
        _ordered(file, f"camera.{key}", getattr(camera, key))
    if camera.min_orbit_speed is not None:
        _ordered(file, "camera.min_orbit_speed, max_orbit_speed", (camera.min_orbit_speed, camera.max_orbit_speed))
    if not camera.zoom_range[0] <= 1.0 <= camera.zoom_range[1]:
        fail(file, "camera.zoom_range", f"must contain 1 (the start camera), got {list(camera.zoom_range)}")
    values = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(camera).items()}
    pool = {k: v for k, v in values.items() if k in POOL_KEYS}
    return pool, {k: v for k, v in values.items() if k not in POOL_KEYS}


def _ordered(file: Path, key: str, pair: tuple[float, float]) -> None:
    if not pair[0] <= pair[1]:
        fail(file, key, f"needs low <= high, got {list(pair)}")


def _volumes(file: Path, entries: tuple[_VolumeEntry, ...]) -> tuple[VolumeSpec, ...]:
    if not entries:
        fail(file, "volumes", "expected a non-empty list of volume entries, got []")
    specs = tuple(_volume(file, entry, f"volumes[{i}]") for i, entry in enumerate(entries))
    names = [s.name for s in specs]
    for i, name in enumerate(names):
        if name in names[:i]:
            fail(file, f"volumes[{i}].name", f"{name!r} is used twice")
    return specs


def _volume(file: Path, entry: _VolumeEntry, key: str) -> VolumeSpec:
    if not NAME.match(entry.name):
        fail(file, f"{key}.name", f"use letters, digits, '_', '-' and '.', got {entry.name!r}")
    if entry.path == PHANTOM:
        source, phantom_shape = None, entry.phantom_shape or PHANTOM_SHAPE
    else:
        source = _existing(file, entry.path, f"{key}.path")
        if entry.phantom_shape is not None:
            fail(file, f"{key}.phantom_shape", "only applies to path: phantom")
        phantom_shape = None
    tf, definition = _transfer_function(file, entry.transfer_function, f"{key}.transfer_function")
    return VolumeSpec(name=entry.name, path=entry.path, source=source, phantom_shape=phantom_shape,
                      transfer_function=tf, tf_definition=definition, videos=entry.videos, split=entry.split)


def _existing(file: Path, written: str, key: str) -> Path:
    """A path as written, resolved against the config's folder; it must exist."""
    resolved = (file.parent / written).resolve()
    if not resolved.exists():
        fail(file, key, f"{resolved} does not exist")
    return resolved


def _transfer_function(file: Path, tf: _TransferFunctionEntry, key: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The entry as the manifest keeps it (a file resolved) and the function it loads."""
    if (tf.preset is None) == (tf.file is None):
        fail(file, key, "needs exactly one of 'preset' or 'file'")
    if tf.preset is not None and tf.name is not None:
        fail(file, f"{key}.name", "only applies with 'file'")
    out: dict[str, Any] = {}
    try:
        if tf.preset is not None:
            loaded = get_preset(tf.preset)
            out["preset"] = loaded.name
        else:
            resolved = _existing(file, tf.file, f"{key}.file")
            loaded = load_transfer_function(resolved, tf.name)
            out.update(file=str(resolved), name=loaded.name)
    except InputError as err:
        if err.path == str(file):
            raise
        fail(file, f"{key}.{'preset' if tf.preset is not None else 'file'}", str(err))
    out["range"] = _range(file, tf.range, f"{key}.range")
    return out, loaded.to_dict()


def _range(file: Path, value: Any, key: str) -> str | list[float] | None:
    if value is None or value == "auto":
        return value
    lo, hi = read_value(tuple[float, float], value, file, key, expected="[low, high]")
    _ordered(file, key, (lo, hi))
    if not lo < hi:
        fail(file, key, f"needs low < high, got {value!r}")
    return [lo, hi]
