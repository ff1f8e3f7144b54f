"""Dataset configs (YAML): what ``volsr dataset`` renders. See docs/dataset.md for the layout.

A config names the image sizes, the scales, the frames per video, the ground truth, the camera
motion and the volumes with their transfer functions and video counts. :func:`read_config`
checks every key and raises a one-line :class:`InputError` ``"<config>: <key>: <problem>"``.
Volume and transfer-function paths are relative to the config file's folder; ``phantom`` names
VolSR's synthetic CT (``phantom_shape`` (z, y, x) voxels, default 128^3).
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import yaml

from volsr_core.errors import InputError, read_text_file
from volsr_core.scene.presets import get_preset, load_transfer_function

SCALES = (2, 4, 8, 16)
GROUND_TRUTH_MODES = ("supersampled", "taa")
PHANTOM = "phantom"
PHANTOM_SHAPE = (128, 128, 128)
TOP_KEYS = ("seed", "hr_size", "scales", "frames_per_video", "previous_frames", "ground_truth", "camera", "volumes")
VOLUME_KEYS = ("name", "path", "phantom_shape", "transfer_function", "videos", "split")
SPLITS = ("train", "val", "test")
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")

# camera keys: candidate_pool's (pool_size is its n) and smooth_random_path's, with their defaults
POOL_DEFAULTS: dict[str, Any] = {"pool_size": 64, "view_angle": 30.0, "distance_range": [0.9, 1.6],
                                 "max_roll": 20.0, "focal_jitter": 0.05}
PATH_DEFAULTS: dict[str, Any] = {"max_orbit_speed": 3.0, "max_elevation_speed": 1.5, "zoom_range": [0.8, 1.5],
                                 "max_elevation": 60.0, "max_zoom_speed": 0.01, "period": 30}


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

    def to_dict(self) -> dict[str, Any]:
        """The config as read, defaults filled in and paths resolved (the manifest's ``config``)."""
        return {"seed": self.seed, "hr_size": list(self.hr_size), "scales": list(self.scales),
                "frames_per_video": self.frames_per_video, "previous_frames": self.previous_frames,
                "ground_truth": dict(self.ground_truth), "camera": {**self.pool, **self.path},
                "volumes": [v.to_dict() for v in self.volumes]}

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
               "volume_index": volume_index, "video_index": video_index}
        return "sha256:" + hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()


class _Checker:
    """Raises one-line InputErrors naming the config file and the key."""

    def __init__(self, file: Path):
        self.file = file

    def fail(self, key: str, problem: str) -> None:
        raise InputError(self.file, f"{key}: {problem}")

    def mapping(self, value: Any, key: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
        if not isinstance(value, Mapping):
            self.fail(key or "(top level)", f"expected a mapping, got {_kind(value)}")
        unknown = [k for k in value if k not in allowed]
        if unknown:
            self.fail(f"{key}.{unknown[0]}" if key else str(unknown[0]), f"unknown key (allowed: {', '.join(allowed)})")
        missing = [k for k in required if k not in value]
        if missing:
            self.fail(f"{key}.{missing[0]}" if key else missing[0], "missing")
        return dict(value)

    def integer(self, value: Any, key: str, low: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(key, f"expected an integer, got {_kind(value)}")
        if low is not None and value < low:
            self.fail(key, f"must be at least {low}, got {value}")
        return int(value)

    def number(self, value: Any, key: str, low: float | None = None, high: float | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"expected a number, got {_kind(value)}")
        if (low is not None and value < low) or (high is not None and value > high):
            self.fail(key, f"must lie in [{low}, {high}], got {value}")
        return float(value)

    def pair(self, value: Any, key: str, low: float | None = None) -> list[float]:
        if not isinstance(value, list) or len(value) != 2:
            self.fail(key, f"expected [low, high], got {value!r}")
        lo, hi = (self.number(v, key, low) for v in value)
        if not lo <= hi:
            self.fail(key, f"needs low <= high, got {value!r}")
        return [lo, hi]

    def text(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            self.fail(key, f"expected a non-empty string, got {_kind(value)}")
        return value

    def existing(self, value: Any, key: str) -> tuple[str, Path]:
        """A path as written and resolved against the config's folder; it must exist."""
        written = self.text(value, key)
        resolved = (self.file.parent / written).resolve()
        if not resolved.exists():
            self.fail(key, f"{resolved} does not exist")
        return written, resolved


def _kind(value: Any) -> str:
    return "nothing" if value is None else f"{type(value).__name__} {value!r}"[:60]


def read_config(path: str | os.PathLike) -> DatasetConfig:
    """Read and check a dataset config (YAML); InputError ``"<path>: <key>: <problem>"`` otherwise."""
    file = Path(path)
    text = read_text_file(file)
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise InputError(file, f"not valid YAML{where}: {getattr(err, 'problem', None) or err}") from None
    check = _Checker(file)
    doc = check.mapping(doc, "", TOP_KEYS, required=TOP_KEYS[:-3] + ("volumes",))
    scales = _scales(check, doc["scales"])
    frames = check.integer(doc["frames_per_video"], "frames_per_video", 1)
    previous = check.integer(doc["previous_frames"], "previous_frames", 0)
    if frames <= previous:
        check.fail("frames_per_video", f"must exceed previous_frames ({previous}), got {frames}")
    camera = check.mapping({} if doc.get("camera") is None else doc["camera"], "camera",
                           tuple(POOL_DEFAULTS) + tuple(PATH_DEFAULTS))
    pool, motion = _camera(check, camera)
    return DatasetConfig(file=file.resolve(), seed=check.integer(doc["seed"], "seed", 0),
                         hr_size=_hr_size(check, doc["hr_size"], scales), scales=scales, frames_per_video=frames,
                         previous_frames=previous, ground_truth=_ground_truth(check, doc.get("ground_truth")),
                         pool=pool, path=motion, volumes=_volumes(check, doc["volumes"]))


def _scales(check: _Checker, value: Any) -> tuple[int, ...]:
    if not isinstance(value, list) or not value:
        check.fail("scales", f"expected a non-empty list of {SCALES}, got {_kind(value)}")
    scales = [check.integer(s, "scales") for s in value]
    bad = [s for s in scales if s not in SCALES]
    if bad:
        check.fail("scales", f"{bad[0]} is not one of {', '.join(map(str, SCALES))}")
    if len(set(scales)) != len(scales):
        check.fail("scales", f"repeats a scale: {scales}")
    return tuple(sorted(scales))


def _hr_size(check: _Checker, value: Any, scales: tuple[int, ...]) -> tuple[int, int]:
    if isinstance(value, list):
        if len(value) != 2:
            check.fail("hr_size", f"expected an integer or [width, height], got {value!r}")
        width, height = (check.integer(v, "hr_size", 1) for v in value)
    else:
        width = height = check.integer(value, "hr_size", 1)
    for s in scales:
        if width % s or height % s:
            check.fail("hr_size", f"{width}x{height} is not divisible by scale {s}")
    return width, height


def _ground_truth(check: _Checker, value: Any) -> dict[str, Any]:
    gt = check.mapping({} if value is None else value, "ground_truth", ("mode", "spp"))
    mode = gt.get("mode", "supersampled")
    if mode not in GROUND_TRUTH_MODES:
        check.fail("ground_truth.mode", f"must be one of {', '.join(GROUND_TRUTH_MODES)}, got {mode!r}")
    return {"mode": mode, "spp": check.integer(gt.get("spp", 16), "ground_truth.spp", 1)}


def _camera(check: _Checker, camera: dict) -> tuple[dict[str, Any], dict[str, Any]]:
    c = {**POOL_DEFAULTS, **PATH_DEFAULTS, **camera}
    pool = {"pool_size": check.integer(c["pool_size"], "camera.pool_size", 1),
            "view_angle": check.number(c["view_angle"], "camera.view_angle", 1.0, 179.0),
            "distance_range": check.pair(c["distance_range"], "camera.distance_range", 0.01),
            "max_roll": check.number(c["max_roll"], "camera.max_roll", 0.0, 180.0),
            "focal_jitter": check.number(c["focal_jitter"], "camera.focal_jitter", 0.0, 1.0)}
    zoom = check.pair(c["zoom_range"], "camera.zoom_range", 0.01)
    if not zoom[0] <= 1.0 <= zoom[1]:
        check.fail("camera.zoom_range", f"must contain 1 (the start camera), got {zoom}")
    path = {"max_orbit_speed": check.number(c["max_orbit_speed"], "camera.max_orbit_speed", 0.0, 90.0),
            "max_elevation_speed": check.number(c["max_elevation_speed"], "camera.max_elevation_speed", 0.0, 90.0),
            "zoom_range": zoom,
            "max_elevation": check.number(c["max_elevation"], "camera.max_elevation", 0.1, 89.9),
            "max_zoom_speed": check.number(c["max_zoom_speed"], "camera.max_zoom_speed", 0.0, 1.0),
            "period": check.integer(c["period"], "camera.period", 1)}
    return pool, path


def _volumes(check: _Checker, value: Any) -> tuple[VolumeSpec, ...]:
    if not isinstance(value, list) or not value:
        check.fail("volumes", f"expected a non-empty list of volume entries, got {_kind(value)}")
    specs = tuple(_volume(check, entry, f"volumes[{i}]") for i, entry in enumerate(value))
    names = [s.name for s in specs]
    for i, name in enumerate(names):
        if name in names[:i]:
            check.fail(f"volumes[{i}].name", f"{name!r} is used twice")
    return specs


def _volume(check: _Checker, entry: Any, key: str) -> VolumeSpec:
    entry = check.mapping(entry, key, VOLUME_KEYS, required=("name", "path", "transfer_function", "videos"))
    name = check.text(entry["name"], f"{key}.name")
    if not NAME.match(name):
        check.fail(f"{key}.name", f"use letters, digits, '_', '-' and '.', got {name!r}")
    if entry["path"] == PHANTOM:
        written, source = PHANTOM, None
        shape = entry.get("phantom_shape", list(PHANTOM_SHAPE))
        if not isinstance(shape, list) or len(shape) != 3:
            check.fail(f"{key}.phantom_shape", f"expected [z, y, x] voxels, got {shape!r}")
        phantom_shape = tuple(check.integer(n, f"{key}.phantom_shape", 8) for n in shape)
    else:
        written, source = check.existing(entry["path"], f"{key}.path")
        if "phantom_shape" in entry:
            check.fail(f"{key}.phantom_shape", "only applies to path: phantom")
        phantom_shape = None
    tf, definition = _transfer_function(check, entry["transfer_function"], f"{key}.transfer_function")
    split = entry.get("split")
    if split is not None and split not in SPLITS:
        check.fail(f"{key}.split", f"expected one of {', '.join(SPLITS)}, got {split!r}")
    return VolumeSpec(name=name, path=written, source=source, phantom_shape=phantom_shape, transfer_function=tf,
                      tf_definition=definition, videos=check.integer(entry["videos"], f"{key}.videos", 1), split=split)


def _transfer_function(check: _Checker, value: Any, key: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """``{preset, range?}`` or ``{file, name?, range?}`` (file resolved) and the function it loads."""
    tf = check.mapping(value, key, ("preset", "file", "name", "range"))
    if ("preset" in tf) == ("file" in tf):
        check.fail(key, "needs exactly one of 'preset' or 'file'")
    out: dict[str, Any] = {}
    try:
        if "preset" in tf:
            if "name" in tf:
                check.fail(f"{key}.name", "only applies with 'file'")
            loaded = get_preset(check.text(tf["preset"], f"{key}.preset"))
            out["preset"] = loaded.name
        else:
            _, resolved = check.existing(tf["file"], f"{key}.file")
            name = None if tf.get("name") is None else check.text(tf["name"], f"{key}.name")
            loaded = load_transfer_function(resolved, name)
            out.update(file=str(resolved), name=loaded.name)
    except InputError as err:
        if err.path == str(check.file):
            raise
        check.fail(f"{key}.{'preset' if 'preset' in tf else 'file'}", str(err))
    out["range"] = _range(check, tf.get("range"), f"{key}.range")
    return out, loaded.to_dict()


def _range(check: _Checker, value: Any, key: str) -> str | list[float] | None:
    if value is None or value == "auto":
        return value
    lo, hi = check.pair(value, key)
    if not lo < hi:
        check.fail(key, f"needs low < high, got {value!r}")
    return [lo, hi]
