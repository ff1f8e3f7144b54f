"""SequenceDataset: training samples from a ``volsr dataset`` folder (docs/dataset.md) as torch tensors."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Sequence

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset

from volsr_core.errors import InputError
from volsr_core.dataset.store import LR_BUFFERS, MANIFEST_FORMAT, frame_pixels_per_voxel, read_json, view_rotations
from volsr_core.sr.history import HistoryFeed

FEATURE_CHANNELS = {name: channels or 1 for name, channels in LR_BUFFERS.items()}
SPLITS = ("train", "val", "test")


class SequenceDataset(Dataset):
    """Samples (video, t) for every frame t >= ``previous_frames`` of the videos in ``split``.

    An item is a dict of float32 tensors (P = ``crop`` HR pixels, p = P / ``scale`` LR pixels;
    the whole frame when ``crop`` is None):

    - ``lr`` (N+1, C, p, p): the LR buffers named by ``features`` stacked as channels in that
      order (color 3, alpha 1, depth 1, max_rgba 4); index 0 is frame t, index k frame t-k;
    - ``motion`` (N+1, 2, p, p): each of those frames' motion vectors to *its own* previous
      frame, LR pixels (dx, dy), +y down (docs/conventions.md; zero for frame 0 of a video);
    - ``jitter`` (N+1, 2): each frame's sub-pixel jitter (jx, jy), LR pixels, +y down;
    - ``hr`` (3, P, P): frame t's ground-truth colour;
    - ``hr_sequence`` (T, 3, P, P), only when ``hr_frames`` T > 1: frames t, t-1, ..., t-T+1's
      ground truth, for unrolling a recurrent network over T frames (``previous_frames`` must
      then count the N frames each step sees plus T - 1);
    - ``taau`` (T, C, P, P), only with ``taau`` (the NetworkConfig of a TAAU-based network): the
      history it takes (C = its ``history_channels``) for the ``hr_frames`` frames t, t-1, ...
      (:class:`~volsr_core.sr.history.HistoryFeed` run over the video from frame 0
      on the LR colour, motion, jitter, motion depth (a version-1 store: the max-alpha depth), the
      view rotations of its cameras and its frames' pixels per voxel (when the video records its
      ``voxel_size``); computed for every video when the dataset is made, so that
      forked loader workers inherit it);
    - ``video``, ``frame``: int64 scalars, the video's number and t (for debugging).

    Crops are aligned across scales: an LR origin (x0, y0) in LR pixels is drawn, and the HR crop
    starts at (scale * x0, scale * y0), so LR pixel (i, j) of the crop covers HR pixels
    [s*i, s*i+s) x [s*j, s*j+s) of the HR crop.

    ``augment`` flips at random, keeping the vectors consistent with the pixels: a horizontal
    flip reverses x of every image and negates motion x and jitter x; a vertical flip reverses y
    and negates motion y and jitter y (a pixel at continuous x moves to W - x, so offsets along x
    change sign).

    Randomness: with ``seed`` an item's crop and flips come from ``default_rng([seed, epoch,
    index])`` (:meth:`set_epoch`), so they repeat exactly; the origin is drawn before the flips,
    so ``augment=False`` with the same seed gives the same crop unflipped. Without ``seed`` each
    call draws fresh OS entropy (safe in DataLoader workers). HDF5 files are opened lazily in each
    worker process, never shared across a fork.
    """

    def __init__(self, root: str | os.PathLike, split: str = "train", scale: int = 4, previous_frames: int = 2,
                 crop: int | None = 128, features: Sequence[str] = ("color", "depth", "max_rgba"),
                 augment: bool = True, seed: int | None = None, hr_frames: int = 1, taau: Any = None):
        self.root = Path(root)
        manifest = _read_manifest(self.root / "manifest.json")
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        unknown = [f for f in features if f not in FEATURE_CHANNELS]
        if unknown or not features:
            raise ValueError(f"features must be a non-empty subset of {tuple(FEATURE_CHANNELS)}, got {features!r}")
        if crop is not None and (crop < scale or crop % scale):
            raise ValueError(f"crop ({crop} HR pixels) must be a positive multiple of the scale ({scale})")
        if previous_frames < 0:
            raise ValueError(f"previous_frames must be at least 0, got {previous_frames}")
        if not 1 <= hr_frames <= previous_frames + 1:
            raise ValueError(f"hr_frames must be 1..previous_frames + 1, got {hr_frames}")
        self.hr_frames = int(hr_frames)
        self.taau = taau
        self._taau: dict[int, np.ndarray] = {}
        self.split, self.scale, self.previous_frames = split, int(scale), int(previous_frames)
        self.crop, self.features, self.augment, self.seed = crop, tuple(features), bool(augment), seed
        self.videos = [v for v in manifest["videos"] if v["split"] == split]
        for video in self.videos:
            self._check_video(video)
        self.samples = [(i, t) for i, v in enumerate(self.videos) for t in range(self.previous_frames, v["frames"])]
        self.epoch = 0
        self._files: dict[int, h5py.File] = {}
        self._pid = os.getpid()
        if self.taau is not None:  # here, not in DataLoader workers: numba's thread pool deadlocks in a forked child
            for video_index in range(len(self.videos)):
                self._taau_frames(video_index)

    @property
    def channels(self) -> int:
        """C, the channels of ``lr``."""
        return sum(FEATURE_CHANNELS[f] for f in self.features)

    def _check_video(self, video: dict[str, Any]) -> None:
        where = self.root / "manifest.json"
        if self.scale not in video["scales"]:
            raise InputError(where, f"video {video['id']} has scales {video['scales']}, not {self.scale}")
        if video["frames"] <= self.previous_frames:
            raise InputError(where, f"video {video['id']} has {video['frames']} frames; previous_frames="
                             f"{self.previous_frames} needs at least {self.previous_frames + 1}")
        voxel = video.get("voxel_size")  # None: a video made before videos recorded it (TAAU then never smooths)
        if voxel is not None and (isinstance(voxel, bool) or not isinstance(voxel, (int, float))
                                  or not math.isfinite(voxel) or voxel <= 0):
            raise InputError(where, f"video {video['id']} has voxel_size {voxel!r}; expected a positive number of mm")
        width, height = video["hr_size"]
        if self.crop is not None and self.crop > min(width, height):
            raise InputError(where, f"video {video['id']} is {width}x{height}, smaller than the crop {self.crop}")

    def set_epoch(self, epoch: int) -> None:
        """Vary the seeded crops and flips from epoch to epoch (no effect without ``seed``)."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        rng = np.random.default_rng(None if self.seed is None else [self.seed, self.epoch, index])
        origin, flips = self.draw(index, rng)
        return self.load(index, origin, *(flips if self.augment else (False, False)))

    def draw(self, index: int, rng: np.random.Generator) -> tuple[tuple[int, int], tuple[bool, bool]]:
        """A random LR crop origin (x0, y0) and (horizontal, vertical) flips for sample ``index``."""
        width, height = self._lr_size(self.samples[index][0])
        pw, ph = self._crop_size(width, height)
        origin = (int(rng.integers(width - pw + 1)), int(rng.integers(height - ph + 1)))
        return origin, (bool(rng.random() < 0.5), bool(rng.random() < 0.5))

    def load(self, index: int, origin: tuple[int, int] = (0, 0), hflip: bool = False,
             vflip: bool = False) -> dict[str, torch.Tensor]:
        """Sample ``index`` cropped at LR ``origin`` (x0, y0), flipped as asked (see the class)."""
        video_index, t = self.samples[index]
        s, n = self.scale, self.previous_frames
        x0, y0 = origin
        pw, ph = self._crop_size(*self._lr_size(video_index))
        h5 = self._file(video_index)
        frames, rows, cols = slice(t - n, t + 1), slice(y0, y0 + ph), slice(x0, x0 + pw)
        lr = np.concatenate([_channels_last(h5[f"lr{s}/{name}"][frames, rows, cols]) for name in self.features], -1)
        motion = h5[f"lr{s}/motion"][frames, rows, cols]
        jitter = h5[f"lr{s}/jitter"][frames]
        hr = h5["hr/color"][t - self.hr_frames + 1:t + 1, s * y0:s * (y0 + ph), s * x0:s * (x0 + pw)]
        lr, motion, jitter, hr = lr[::-1], motion[::-1].copy(), jitter[::-1].copy(), hr[::-1]  # index k = frame t-k
        if hflip:
            lr, motion, hr = lr[:, :, ::-1], motion[:, :, ::-1], hr[:, :, ::-1]
            motion[..., 0] *= -1
            jitter[:, 0] *= -1
        if vflip:
            lr, motion, hr = lr[:, ::-1], motion[:, ::-1], hr[:, ::-1]
            motion[..., 1] *= -1
            jitter[:, 1] *= -1
        hr = _tensor(hr.transpose(0, 3, 1, 2))
        taau = None
        if self.taau is not None:
            taau = self._taau_frames(video_index)[t - self.hr_frames + 1:t + 1, s * y0:s * (y0 + ph),
                                                  s * x0:s * (x0 + pw)][::-1]
            taau = taau[:, :, ::-1] if hflip else taau
            taau = taau[:, ::-1] if vflip else taau
        item = {"lr": _tensor(lr.transpose(0, 3, 1, 2)), "motion": _tensor(motion.transpose(0, 3, 1, 2)),
                "jitter": _tensor(jitter), "hr": hr[0],
                "video": torch.tensor(int(self.videos[video_index]["id"][1:])), "frame": torch.tensor(t)}
        if self.hr_frames > 1:
            item["hr_sequence"] = hr
        if taau is not None:
            item["taau"] = _tensor(taau.transpose(0, 3, 1, 2))
        return item

    def _taau_frames(self, video_index: int) -> np.ndarray:
        """(T, H, W, C) float16: the TAAU history the network takes for each frame of the video (its
        :class:`~volsr_core.sr.history.HistoryFeed` over the whole video at this scale), computed once."""
        if video_index not in self._taau:
            h5, s = self._file(video_index), self.scale
            colour, motion, jitter = (h5[f"lr{s}/{k}"][()].astype(np.float32) for k in ("color", "motion", "jitter"))
            depth = h5[f"lr{s}/motion_depth" if f"lr{s}/motion_depth" in h5 else f"lr{s}/depth"][()].astype(np.float32)
            rotation = view_rotations(h5["cameras"][()])
            fineness = frame_pixels_per_voxel(self.videos[video_index], colour.shape[1])
            slabs = self._slabs(video_index, h5)
            feed = HistoryFeed(self.taau)
            self._taau[video_index] = np.stack([feed(colour[t], motion[t], tuple(jitter[t]), depth[t], rotation[t],
                                                     fineness[t], slabs=None if slabs is None else slabs[t])
                                                for t in range(len(colour))]).astype(np.float16)
        return self._taau[video_index]

    def _slabs(self, video_index: int, h5: h5py.File) -> np.ndarray | None:
        """(T, K, h, w, SLAB_CHANNELS) float32: the video's depth slabs at this scale where the network refines the
        layered TAAU (``taau_slabs`` K), else None; InputError naming the store where it holds no K slabs."""
        wanted = int(getattr(self.taau, "taau_slabs", 0))
        if not wanted:
            return None
        key, file = f"lr{self.scale}/slabs", self.root / self.videos[video_index]["file"]
        have = h5[key].shape[1] if key in h5 else 0
        if have != wanted:
            raise slabs_mismatch(file, have, wanted, self.scale)
        return h5[key][()].astype(np.float32)

    def _lr_size(self, video_index: int) -> tuple[int, int]:
        width, height = self.videos[video_index]["hr_size"]
        return width // self.scale, height // self.scale

    def _crop_size(self, width: int, height: int) -> tuple[int, int]:
        """(width, height) of the LR crop."""
        return (width, height) if self.crop is None else (self.crop // self.scale,) * 2

    def _file(self, video_index: int) -> h5py.File:
        """The video's store, opened on first use in this process."""
        if self._pid != os.getpid():  # a forked worker: never use the parent's handles
            self._files, self._pid = {}, os.getpid()
        if video_index not in self._files:
            self._files[video_index] = h5py.File(self.root / self.videos[video_index]["file"], "r")
        return self._files[video_index]

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_files": {}}


def slabs_mismatch(file: Path, have: int, wanted: int, scale: int) -> InputError:
    """The error for a video store holding ``have`` depth slabs at ``scale`` where the network refines the layered
    TAAU of ``wanted`` (``taau_slabs``)."""
    return InputError(file, f"holds {have} depth slabs at {scale}x (lr{scale}/slabs), the network refines the layered "
                            f"TAAU of {wanted}: make the dataset with `slabs: {wanted}`")


def _read_manifest(path: Path) -> dict[str, Any]:
    manifest = read_json(path)
    if manifest is None:
        raise InputError(path, "missing or not JSON; make the dataset with `volsr dataset CONFIG --out DIR`")
    if manifest.get("format") != MANIFEST_FORMAT:
        raise InputError(path, f"not a VolSR dataset manifest ('format' is {manifest.get('format')!r})")
    return manifest


def _channels_last(array: np.ndarray) -> np.ndarray:
    """(T, h, w) -> (T, h, w, 1); (T, h, w, C) as it is."""
    return array[..., None] if array.ndim == 3 else array


def _tensor(array: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(array, dtype=np.float32))
