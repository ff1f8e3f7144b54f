"""The on-disk dataset: one HDF5 store per video, its JSON entry, and the manifest (docs/dataset.md).

Stores are written frame by frame into ``.vNNNN.h5.part`` and renamed to ``vNNNN.h5`` when
whole; JSON files are written atomically. A write the disk refuses (full, quota, file-size limit)
stops the store with a one-line OutputError and deletes its ``.part`` file.

Checksums are ``"sha256:<hex>"`` of each dataset's bytes in C order, as stored (frame axis first, so
frames are hashed in order as they are written).
"""
from __future__ import annotations

import hashlib
import io
import json
import os
from importlib.resources import files
from pathlib import Path
from typing import Any, Mapping

import h5py
import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError, write_error
from volsr_core.render.layout import SLAB_CHANNELS

STORE_FORMAT = "volsr-video"
MANIFEST_FORMAT = "volsr-dataset"
VERSION = 2  # 2: lr{s}/motion_depth and lr{s}/centred; ray starts jittered per frame and ground-truth sample
GZIP_LEVEL = 4
CAMERA_COLUMNS = 22
# LR feature buffers: name -> channels (None: no channel axis)
LR_BUFFERS: dict[str, int | None] = {"color": 3, "alpha": None, "depth": None, "max_rgba": 4, "motion_depth": None}
IMAGE_DTYPE = np.dtype(np.float16)
VECTOR_DTYPE = np.dtype(np.float32)


def store_layout(frames: int, hr_size: tuple[int, int], scales: tuple[int, ...],
                 slabs: int = 0) -> dict[str, tuple[tuple, np.dtype]]:
    """Every dataset of a video store: name -> (shape, dtype). ``hr_size`` is (width, height); ``slabs`` K > 0
    adds each scale's depth slabs (``lr{s}/slabs``, (frames, K, h, w, SLAB_CHANNELS): premultiplied RGBA and
    motion in LR pixels, :attr:`~volsr_core.render.features.FeatureFrame.slabs`)."""
    width, height = hr_size
    layout: dict[str, tuple[tuple, np.dtype]] = {"hr/color": ((frames, height, width, 3), IMAGE_DTYPE)}
    for s in scales:
        h, w = height // s, width // s
        for name, channels in LR_BUFFERS.items():
            layout[f"lr{s}/{name}"] = ((frames, h, w) + ((channels,) if channels else ()), IMAGE_DTYPE)
        layout[f"lr{s}/centred"] = ((frames, h, w, 3), IMAGE_DTYPE)  # unjittered colour: the reduced-size render
        layout[f"lr{s}/motion"] = ((frames, h, w, 2), VECTOR_DTYPE)
        layout[f"lr{s}/jitter"] = ((frames, 2), VECTOR_DTYPE)
        if slabs:
            layout[f"lr{s}/slabs"] = ((frames, slabs, h, w, SLAB_CHANNELS), VECTOR_DTYPE)
    layout["cameras"] = ((frames, CAMERA_COLUMNS), np.dtype(np.float64))
    return layout


def view_rotations(cameras: np.ndarray) -> np.ndarray:
    """Degrees the view turned into each frame from the one before (0 for frame 0), from the store's
    ``cameras`` rows (position, then focal point, mm): the angle between directions of projection."""
    rows = np.asarray(cameras, dtype=np.float64)
    forward = rows[:, 3:6] - rows[:, 0:3]
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    cos = np.clip(np.sum(forward[1:] * forward[:-1], axis=1), -1.0, 1.0)
    return np.concatenate([[0.0], np.degrees(np.arccos(cos))])


def frame_pixels_per_voxel(entry: Mapping[str, Any], height: int) -> list[float | None]:
    """Per frame of a video's JSON ``entry``, how many pixels of an image ``height`` pixels tall the volume's
    smallest voxel spacing spans at the focal point (as the renderer's ``FeatureFrame.pixels_per_voxel``);
    None for each frame of an entry written before videos recorded ``voxel_size``."""
    from volsr_core.scene.camera import Camera

    voxel = entry.get("voxel_size")
    return [None if voxel is None else float(voxel) / Camera.from_dict(c).pixel_size_at_focus(height)
            for c in entry["cameras"]]


def raw_bytes(layout: Mapping[str, tuple[tuple, np.dtype]]) -> int:
    """Bytes of all datasets before compression."""
    return sum(int(np.prod(shape)) * dtype.itemsize for shape, dtype in layout.values())


def part_path(path: Path) -> Path:
    """Where a store is written before it is complete: ``.vNNNN.h5.part`` beside ``vNNNN.h5``."""
    return path.with_name(f".{path.name}.part")


def create_datasets(h5: h5py.File, layout: Mapping[str, tuple[tuple, np.dtype]]) -> None:
    """Images one frame per chunk, gzip + shuffle; the small per-frame vectors (2-D) contiguous."""
    for name, (shape, dtype) in layout.items():
        if len(shape) > 2:
            h5.create_dataset(name, shape=shape, dtype=dtype, chunks=(1,) + shape[1:],
                              compression="gzip", compression_opts=GZIP_LEVEL, shuffle=True)
        else:
            h5.create_dataset(name, shape=shape, dtype=dtype)


class GuardedFile(io.FileIO):
    """The file HDF5 writes a store through: it keeps the first error of a write the disk refuses in
    :attr:`error` and from then on drops every write. HDF5 itself never sees the failure, which on a full
    disk left it in a state that crashed the interpreter at exit (a segfault after hundreds of lines of
    HDF5 errors); the store is deleted anyway, and its writer raises :attr:`error` as one line."""

    error: OSError | None = None

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        done = 0
        while self.error is None and done < len(view):  # regular files may take a write in parts
            try:
                done += super().write(view[done:])
            except OSError as err:
                self.error = err
        return len(view)

    def truncate(self, size: int | None = None) -> int:
        if self.error is None:
            try:
                return super().truncate(size)
            except OSError as err:
                self.error = err
        return self.tell() if size is None else size


class StoreWriter:
    """Writes one video store frame by frame into its ``.part`` file, hashing as it goes.

    ``with StoreWriter(path, layout, attrs) as w: w.write_frame(frame_dict) ...``; leaving the
    block normally renames the ``.part`` file to ``path`` (then :attr:`checksums` is set); an
    exception deletes it. Frames must come in order 0..T-1. Every frame is flushed to disk as it
    is written, so a full disk stops the store at that frame with an OutputError naming ``path``.
    """

    def __init__(self, path: Path, layout: Mapping[str, tuple[tuple, np.dtype]], attrs: Mapping[str, Any]):
        self.path = Path(path)
        self.part = part_path(self.path)
        self.layout = dict(layout)
        self.frames = next(iter(self.layout.values()))[0][0]
        self._hashes = {name: hashlib.sha256() for name in self.layout}
        self._next = 0
        self.checksums: dict[str, str] = {}
        self._h5: h5py.File | None = None
        try:
            self._file = GuardedFile(self.part, "w+")
        except OSError as err:
            raise write_error(self.path, err) from None
        try:
            self._h5 = h5py.File(self._file, "w")
            self._h5.attrs.update(dict(attrs))
            create_datasets(self._h5, self.layout)
            self._flush()
        except BaseException:
            self._discard()
            raise

    def write_frame(self, frame: Mapping[str, np.ndarray]) -> None:
        """Store one frame of every dataset (converted to the stored dtype) and flush it to disk."""
        if self._next >= self.frames:
            raise ValueError(f"{self.path.name}: all {self.frames} frames are written")
        for name, (shape, dtype) in self.layout.items():
            value = np.ascontiguousarray(frame[name], dtype=dtype).reshape(shape[1:])
            self._h5[name][self._next] = value
            self._hashes[name].update(value.tobytes())
        self._next += 1
        self._flush()

    def _flush(self) -> None:
        """Flush HDF5's buffers to the file; OutputError naming the store when the disk refused a write."""
        self._h5.flush()
        if self._file.error is not None:
            raise write_error(self.path, self._file.error)

    def _discard(self) -> None:
        """Close everything and delete the ``.part`` file."""
        if self._h5 is not None:
            self._h5.close()
        self._file.close()
        self.part.unlink(missing_ok=True)

    def __enter__(self) -> "StoreWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None or self._next != self.frames:
            self._discard()
            if exc_type is None:
                raise ValueError(f"{self.path.name}: only {self._next} of {self.frames} frames were written")
            return
        self._h5.close()
        self._file.close()
        if self._file.error is not None:
            self.part.unlink(missing_ok=True)
            raise write_error(self.path, self._file.error)
        os.replace(self.part, self.path)
        self.checksums = {name: "sha256:" + h.hexdigest() for name, h in self._hashes.items()}


def checksum(array: np.ndarray) -> str:
    """``"sha256:<hex>"`` of an array's bytes in C order."""
    return "sha256:" + hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def store_checksums(path: Path) -> dict[str, str]:
    """Checksums of every dataset in a store, read back frame by frame."""
    sums: dict[str, str] = {}
    with h5py.File(path, "r") as h5:
        def visit(name: str, node: Any) -> None:
            if isinstance(node, h5py.Dataset):
                h = hashlib.sha256()
                for t in range(node.shape[0]):
                    h.update(np.ascontiguousarray(node[t]).tobytes())
                sums[name] = "sha256:" + h.hexdigest()
        h5.visititems(visit)
    return sums


def write_json(path: Path, doc: Mapping[str, Any]) -> None:
    """Write JSON atomically (temporary file beside it, then rename)."""
    with atomic_write(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")


def read_json(path: Path) -> dict[str, Any] | None:
    """The JSON object in ``path``, or None when it is absent or unreadable (treated as incomplete)."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return doc if isinstance(doc, dict) else None


def manifest_schema() -> dict[str, Any]:
    """``resources/schemas/dataset-manifest.schema.json``."""
    text = (files("volsr_core.resources") / "schemas" / "dataset-manifest.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def validate_manifest(path: str | os.PathLike, checksums: bool = True) -> dict[str, Any]:
    """Check a dataset's ``manifest.json`` and return it; InputError (one line) on the first problem.

    Checks the JSON schema, that video ids are unique and each lies in exactly the split it
    names, that every listed store exists and (``checksums=True``, reading every array) that
    its datasets and their SHA-256 match the manifest.
    """
    import jsonschema

    path = Path(path)
    doc = read_json(path)
    if doc is None:
        raise InputError(path, "missing or not a JSON object")
    try:
        jsonschema.validate(doc, manifest_schema())
    except jsonschema.ValidationError as err:
        where = "/".join(str(p) for p in err.absolute_path) or "(top)"
        raise InputError(path, f"does not match the manifest schema at {where}: {err.message}") from None
    _check_splits(path, doc)
    for video in doc["videos"]:
        store = path.parent / video["file"]
        if not store.is_file():
            raise InputError(path, f"video {video['id']}: {video['file']} does not exist")
        if checksums:
            _check_checksums(path, video, store)
    return doc


def _check_splits(path: Path, doc: Mapping[str, Any]) -> None:
    ids = [v["id"] for v in doc["videos"]]
    if len(set(ids)) != len(ids):
        raise InputError(path, "a video id is listed twice")
    where = {}
    for split, members in doc["splits"].items():
        for vid in members:
            if vid in where:
                raise InputError(path, f"video {vid} is in splits {where[vid]} and {split}")
            where[vid] = split
    for video in doc["videos"]:
        if where.get(video["id"]) != video["split"]:
            raise InputError(path, f"video {video['id']} says split {video['split']} but the splits list "
                             f"{where.get(video['id'], 'none')}")
    if set(where) != set(ids):
        raise InputError(path, f"splits name videos that are not listed: {sorted(set(where) - set(ids))}")


def _check_checksums(path: Path, video: Mapping[str, Any], store: Path) -> None:
    try:
        actual = store_checksums(store)
    except OSError as err:
        raise InputError(path, f"video {video['id']}: cannot read {video['file']}: {err}") from None
    expected = video["checksums"]
    if set(actual) != set(expected):
        raise InputError(path, f"video {video['id']}: {video['file']} holds datasets {sorted(actual)}, "
                         f"the manifest lists {sorted(expected)}")
    for name, value in expected.items():
        if actual[name] != value:
            raise InputError(path, f"video {video['id']}: checksum of {name} in {video['file']} does not match")
