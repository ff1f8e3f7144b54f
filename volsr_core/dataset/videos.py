"""Training sequences: camera-path videos of volumes, LR feature buffers at every scale, HR ground truth.

``generate(config, out)`` renders every planned video that is not complete yet (docs/dataset.md):

- Videos are numbered globally in config order (volume by volume). Everything random comes from
  ``numpy.random.default_rng([seed, tag, ...])`` keyed by what it is for, so a video's content
  does not depend on the shard, the run or the order: the volume's candidate pool from
  ``[seed, 1, volume index]``, the volume's split from ``[seed, 2, volume index]``, a video's
  start camera and path from ``[seed, 3, volume index, video index within the volume]``.
- Per frame t: the HR ground truth (:func:`ground_truth_frames`), and per scale s one LR render
  without anti-aliasing, jittered by ``halton_jitter(t, ceil(8 s^2))`` (FSR2's phase count),
  with the previous frame's camera so that the motion vectors point to frame t-1 (zero at t=0),
  plus the unjittered LR colour (``centred``: what a reduced-size render shows, for the baselines)
  and, with ``slabs`` K > 0, the same jittered frame cut into K depth slabs (``lr{s}/slabs``, what the
  layered TAAU accumulates) in a pass of its own, so that the other buffers are those of a dataset without.
  Ray starts are jittered per pixel (interleaved gradient noise) with the frame number as seed, and
  per ground-truth sample.
- A video's store is written frame by frame to ``.vNNNN.h5.part`` and renamed when whole; then
  its JSON entry is written; then ``manifest.json`` is rebuilt from every entry present.
"""
from __future__ import annotations

import io
import re
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import h5py
import numpy as np

from volsr_core import __version__
from volsr_core.errors import InputError, OutputError
from volsr_core.render.raycaster import RayCaster
from volsr_core.scene.camera import Camera
from volsr_core.scene.camera_paths import candidate_pool, random_start, smooth_random_path
from volsr_core.scene.presets import place_on_volume
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.dataset.config import PHANTOM, SPLITS, DatasetConfig, VolumeSpec
from volsr_core.temporal.ground_truth import ground_truth_frames
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.dataset.store import (
    CAMERA_COLUMNS, MANIFEST_FORMAT, STORE_FORMAT, VERSION, StoreWriter, create_datasets, raw_bytes,
    read_json, store_layout, write_json,
)

POOL_TAG, SPLIT_TAG, VIDEO_TAG = 1, 2, 3
STALE_PART = re.compile(r"^\.v(\d{4,})\.(?:h5|json)(?:\..+)?\.part$")


def rng_for(seed: int, tag: int, *keys: int) -> np.random.Generator:
    """The generator for one purpose (``tag``) and place (``keys``): ``default_rng([seed, tag, *keys])``."""
    return np.random.default_rng([seed, tag, *keys])


# plan --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VideoPlan:
    """One planned video: global ``number``, its volume, its index there, split and fingerprint."""

    number: int
    volume_index: int
    video_index: int
    split: str
    fingerprint: str

    @property
    def id(self) -> str:
        return f"v{self.number:04d}"

    @property
    def file(self) -> str:
        """The store, relative to the dataset folder."""
        return f"videos/{self.id}.h5"

    @property
    def entry(self) -> str:
        """The JSON entry, relative to the dataset folder."""
        return f"videos/{self.id}.json"


def split_of_videos(n: int, rng: np.random.Generator) -> list[str]:
    """The split of each of ``n`` videos: shuffled by ``rng`` and cut 80/10/10 by count, val and
    test rounded to the nearest video but at least one each when ``n >= 3`` (none below 3)."""
    n_held = max(1, round(0.1 * n)) if n >= 3 else 0
    order = rng.permutation(n)
    splits = [""] * n
    for rank, video in enumerate(order):
        splits[video] = "train" if rank < n - 2 * n_held else "val" if rank < n - n_held else "test"
    return splits


def plan_videos(config: DatasetConfig) -> list[VideoPlan]:
    """Every video of the config, numbered globally in config order."""
    plans: list[VideoPlan] = []
    for vi, spec in enumerate(config.volumes):
        splits = [spec.split] * spec.videos if spec.split else split_of_videos(spec.videos,
                                                                                rng_for(config.seed, SPLIT_TAG, vi))
        plans += [VideoPlan(len(plans) + k, vi, k, splits[k], config.fingerprint(vi, k)) for k in range(spec.videos)]
    return plans


def parse_shard(text: str) -> tuple[int, int]:
    """``'i/n'`` -> (i, n) with 0 <= i < n; InputError naming ``--shard`` otherwise."""
    match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not match or not int(match[1]) < int(match[2]):
        raise InputError("--shard", f"expected i/n with 0 <= i < n (e.g. 0/4), got {text!r}")
    return int(match[1]), int(match[2])


# volumes and cameras -------------------------------------------------------------------------------
@dataclass
class DatasetVolume:
    """A loaded volume with its placed transfer function, ray caster and candidate pool."""

    name: str
    volume: Volume
    transfer_function: TransferFunction
    caster: RayCaster
    pool: list[Camera]


def load_volume(spec: VolumeSpec) -> Volume:
    """The volume a config entry names: its file, or the phantom of its shape."""
    from volsr_core.io import make_phantom

    if spec.path == PHANTOM:
        return Volume.from_record(make_phantom(shape=spec.phantom_shape))
    return Volume.load(spec.source)


def load_dataset_volume(config: DatasetConfig, volume_index: int, device: str = "cpu") -> DatasetVolume:
    """Load the volume ``volume_index`` of the config and place its transfer function on it:
    the design range onto ``range`` [lo, hi], ``auto`` as :func:`place_on_volume` (kept for HU
    presets on HU volumes, else onto the volume's 0.5-99.5 percentiles), kept without ``range``."""
    spec = config.volumes[volume_index]
    volume = load_volume(spec)
    tf = place_on_volume(TransferFunction.from_dict(spec.tf_definition), volume, spec.transfer_function["range"])
    pool_args = dict(config.pool)
    n = pool_args.pop("pool_size")
    pool_args["distance_range"] = tuple(pool_args["distance_range"])
    pool = candidate_pool(volume.bounds, n, rng_for(config.seed, POOL_TAG, volume_index), **pool_args)
    caster = RayCaster(volume, tf, device=device, start_jitter="ign")  # ray starts jittered per frame / sample
    return DatasetVolume(spec.name, volume, tf, caster, pool)


def camera_path(config: DatasetConfig, source: DatasetVolume, plan: VideoPlan) -> list[Camera]:
    """The video's cameras: a random start from the volume's pool, then a smooth random path (its top orbit
    speed drawn log-uniformly between ``min_orbit_speed`` and ``max_orbit_speed`` when the former is set)."""
    rng = rng_for(config.seed, VIDEO_TAG, plan.volume_index, plan.video_index)
    start = random_start(source.pool, rng)
    args = {**config.path, "zoom_range": tuple(config.path["zoom_range"])}
    low = args.pop("min_orbit_speed", None)
    if low is not None:
        args["max_orbit_speed"] = float(np.exp(rng.uniform(np.log(low), np.log(args["max_orbit_speed"]))))
    return smooth_random_path(start, config.frames_per_video, rng, bounds=source.volume.bounds, **args)


def camera_row(camera: Camera) -> np.ndarray:
    """The store's ``cameras`` row: position, focal point, view up, view angle, parallel (0/1),
    parallel scale, clipping range, then zeros up to :data:`CAMERA_COLUMNS` (float64, mm and degrees)."""
    row = np.zeros(CAMERA_COLUMNS)
    row[:14] = [*camera.position, *camera.focal_point, *camera.view_up, camera.view_angle,
                float(camera.parallel_projection), camera.parallel_scale, *camera.clipping_range]
    return row


# rendering ---------------------------------------------------------------------------------------
def render_frames(config: DatasetConfig, source: DatasetVolume, cameras: list[Camera]) -> Iterator[dict[str, np.ndarray]]:
    """Per camera, the store's datasets for that frame (name -> array without the frame axis).

    The LR arrays are views into buffers reused by the next frame: store them before advancing.
    """
    width, height = config.hr_size
    truth = ground_truth_frames(source.caster, cameras, width, height, **config.ground_truth)
    buffers: dict[int, np.ndarray | None] = dict.fromkeys(config.scales)
    for t, (camera, hr) in enumerate(zip(cameras, truth)):
        frame = {"hr/color": hr, "cameras": camera_row(camera)}
        for s in config.scales:
            jitter = halton_jitter(t, jitter_phases(s))
            centred = source.caster.render_color(camera, width // s, height // s, seed=t)
            lr = source.caster.render(camera, width // s, height // s, jitter=jitter,
                                     previous_camera=cameras[t - 1] if t else None, seed=t, out=buffers[s])
            buffers[s] = lr.data
            frame.update({f"lr{s}/color": lr.color, f"lr{s}/alpha": lr.alpha, f"lr{s}/depth": lr.depth,
                          f"lr{s}/max_rgba": lr.max_rgba, f"lr{s}/motion_depth": lr.motion_depth,
                          f"lr{s}/centred": centred, f"lr{s}/motion": lr.motion,
                          f"lr{s}/jitter": np.asarray(jitter, dtype=np.float32)})
            if config.slabs:  # a pass of its own: with slabs, rays go on past early termination (other colours)
                frame[f"lr{s}/slabs"] = source.caster.render(
                    camera, width // s, height // s, jitter=jitter, previous_camera=cameras[t - 1] if t else None,
                    seed=t, slabs=config.slabs).slabs
        yield frame


def write_video(config: DatasetConfig, source: DatasetVolume, plan: VideoPlan, out: Path,
                on_frame: Callable[[int], Any] = lambda n: None) -> dict[str, Any]:
    """Render one video into ``out/videos``: the store (via ``.part``), then its JSON entry; returns the entry."""
    cameras = camera_path(config, source, plan)
    layout = store_layout(config.frames_per_video, config.hr_size, config.scales, config.slabs)
    attrs = {"video": plan.id, "volume": source.name, "format": STORE_FORMAT, "version": VERSION}
    with StoreWriter(out / plan.file, layout, attrs) as writer:
        for frame in render_frames(config, source, cameras):
            writer.write_frame(frame)
            on_frame(1)
    entry = {"id": plan.id, "file": plan.file, "volume": source.name, "split": plan.split,
             "frames": config.frames_per_video, "hr_size": list(config.hr_size), "scales": list(config.scales),
             "transfer_function": source.transfer_function.to_dict(), "cameras": [c.to_dict() for c in cameras],
             "voxel_size": voxel_size(source.volume), "ground_truth": dict(config.ground_truth),
             "checksums": writer.checksums, "fingerprint": plan.fingerprint}
    write_json(out / plan.entry, entry)
    return entry


def voxel_size(volume: Volume) -> float:
    """mm: the volume's smallest voxel spacing, what a frame's pixels per voxel count
    (:func:`~volsr_core.dataset.store.frame_pixels_per_voxel`)."""
    return float(min(volume.spacing))


# resuming and the manifest -----------------------------------------------------------------------
def record_voxel_sizes(config: DatasetConfig, out: Path, plans: list[VideoPlan]) -> int:
    """Add ``voxel_size`` to the JSON entries of complete videos written before entries had it (loading
    each volume once, rendering nothing); returns how many entries were updated."""
    sizes: dict[int, float] = {}
    updated = 0
    for plan in plans:
        entry = read_json(out / plan.entry)
        if not is_complete(out, plan) or "voxel_size" in entry:
            continue
        if plan.volume_index not in sizes:
            sizes[plan.volume_index] = voxel_size(load_volume(config.volumes[plan.volume_index]))
        write_json(out / plan.entry, {**entry, "voxel_size": sizes[plan.volume_index]})
        updated += 1
    return updated


def is_complete(out: Path, plan: VideoPlan) -> bool:
    """Cheap check: the store and the JSON entry exist and the entry's fingerprint is the plan's."""
    entry = read_json(out / plan.entry)
    return entry is not None and entry.get("fingerprint") == plan.fingerprint and (out / plan.file).is_file()


def remove_stale_parts(out: Path, shard: tuple[int, int]) -> list[Path]:
    """Delete the ``.part`` files a killed run left for this shard's videos (and, unsharded, of the
    manifest); other shards' may be in use. Returns what was deleted."""
    index, count = shard
    stale = [f for f in (out / "videos").iterdir()
             if (m := STALE_PART.match(f.name)) and int(m[1]) % count == index]
    if count == 1:
        stale += list(out.glob(".manifest.json.*.part"))
    for f in stale:
        f.unlink(missing_ok=True)
    return stale


def renderer_version(device: str) -> str:
    import numba

    return f"volsr ray caster {__version__} ({device}, numba {numba.__version__})"


def build_manifest(config: DatasetConfig, out: Path, plans: list[VideoPlan], device: str = "cpu") -> dict[str, Any]:
    """The manifest from the complete videos present (planned id, matching fingerprint, store there)."""
    videos = []
    for plan in plans:
        entry = read_json(out / plan.entry)
        if entry is not None and entry.get("fingerprint") == plan.fingerprint and (out / plan.file).is_file():
            videos.append({**entry, "split": plan.split})
    return {"format": MANIFEST_FORMAT, "version": VERSION, "renderer_version": renderer_version(device),
            "volsr_version": __version__, "config": config.to_dict(), "complete": len(videos) == len(plans),
            "videos": videos, "splits": {s: [v["id"] for v in videos if v["split"] == s] for s in SPLITS}}


# the plan printed before starting ----------------------------------------------------------------
@dataclass(frozen=True)
class Measurement:
    """Seconds to render frame 0 (with any TAA warm-up) and each later frame (HR ground truth and
    every LR scale), and the compressed / raw size of one frame's datasets."""

    first_frame_s: float
    frame_s: float
    compression: float

    def video_seconds(self, frames: int) -> float:
        return self.first_frame_s + (frames - 1) * self.frame_s


def measure(config: DatasetConfig, source: DatasetVolume, cameras: list[Camera]) -> Measurement:
    """Render the first two frames of ``cameras`` as the generator does, timing each."""
    source.caster.render(cameras[0], 8, 8)  # compile (or load) the renderer outside the timing
    layout = store_layout(1, config.hr_size, config.scales, config.slabs)
    seconds, ratio = [], 1.0
    start = time.perf_counter()
    for frame in render_frames(config, source, cameras[:2]):
        seconds.append(time.perf_counter() - start)
        ratio = _compression(layout, frame)
        start = time.perf_counter()
    return Measurement(seconds[0], seconds[-1], ratio)


def _compression(layout: dict[str, tuple[tuple, np.dtype]], frame: dict[str, np.ndarray]) -> float:
    """Bytes of a one-frame store written in memory with the real filters, over its raw bytes."""
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as h5:
        create_datasets(h5, layout)
        for name, (shape, dtype) in layout.items():
            h5[name][0] = np.asarray(frame[name], dtype=dtype).reshape(shape[1:])
    return len(buffer.getvalue()) / raw_bytes(layout)


def check_free_space(out: Path, config: DatasetConfig, todo: list[VideoPlan], measured: Measurement) -> None:
    """OutputError naming ``out`` when its file system has less free space than the videos to render are
    expected to take (gzip-compressed, as :func:`measure` found on one frame)."""
    need = len(todo) * raw_bytes(store_layout(config.frames_per_video, config.hr_size, config.scales, config.slabs))
    need *= measured.compression
    free = shutil.disk_usage(out).free
    if need > free:
        raise OutputError(out, f"not enough free space: {len(todo)} videos need about {_size(need)}, "
                          f"{_size(free)} is free")


def _size(n_bytes: float) -> str:
    for unit, factor in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n_bytes >= factor:
            return f"{n_bytes / factor:.2f} {unit}"
    return f"{n_bytes:.0f} B"


def _duration(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    h, m = divmod(m, 60)
    return f"{h}h{m:02d}m{s:02d}s" if h else f"{m}m{s:02d}s"


def plan_text(config: DatasetConfig, plans: list[VideoPlan], mine: list[VideoPlan], todo: list[VideoPlan],
              shard: tuple[int, int], measured: Measurement | None, probe_volume: str, device: str) -> str:
    """What will be rendered, how much disk it takes and how long it should last."""
    frames = config.frames_per_video
    width, height = config.hr_size
    lr = ", ".join(f"{width // s}x{height // s} (x{s})" for s in config.scales)
    gt = config.ground_truth
    lines = [f"dataset {config.file}: {len(plans)} videos x {frames} frames, "
             f"{len(mine)} in shard {shard[0]}/{shard[1]}, {len(mine) - len(todo)} complete, "
             f"{len(todo)} to render ({len(todo) * frames} frames)",
             f"  HR {width}x{height} ({gt['mode']}, {gt['spp']} spp); LR {lr}"]
    if measured is not None:
        raw = len(todo) * raw_bytes(store_layout(frames, config.hr_size, config.scales, config.slabs))
        lines += [f"  disk: {_size(raw)} of raw arrays, about {_size(raw * measured.compression)} gzip-compressed "
                  f"(ratio {measured.compression:.2f} measured on one frame)",
                  f"  time: about {_duration(len(todo) * measured.video_seconds(frames))} on {device} "
                  f"({measured.frame_s:.2f} s per frame measured on {probe_volume}, all scales)"]
    return "\n".join(lines)


# the whole run -----------------------------------------------------------------------------------
def generate(config: DatasetConfig, out: str | Path, shard: tuple[int, int] = (0, 1), device: str = "cpu",
             log: Callable[[str], Any] = print, progress: bool = True) -> dict[str, Any]:
    """Render this shard's incomplete videos into ``out`` and (re)write ``manifest.json``; returns it.

    Prints the plan (videos, frames, expected disk and time from rendering two probe frames of
    the first volume to render) before starting and shows a progress bar over frames.
    """
    from tqdm import tqdm

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder")
    (out / "videos").mkdir(parents=True, exist_ok=True)
    plans = plan_videos(config)
    mine = [p for p in plans if p.number % shard[1] == shard[0]]
    remove_stale_parts(out, shard)
    todo = [p for p in mine if not is_complete(out, p)]
    recorded = record_voxel_sizes(config, out, mine)
    if recorded:
        log(f"{out}: recorded the voxel size of {recorded} video(s) made before videos recorded it")
    source = load_dataset_volume(config, todo[0].volume_index, device) if todo else None
    measured = measure(config, source, camera_path(config, source, todo[0])) if source else None
    log(plan_text(config, plans, mine, todo, shard, measured, source.name if source else "", device))
    if measured is not None:
        check_free_space(out, config, todo, measured)
    started = time.perf_counter()
    with tqdm(total=len(todo) * config.frames_per_video, unit="frame", desc="dataset", disable=not progress,
              file=sys.stderr) as bar:
        for plan in todo:
            if source.name != config.volumes[plan.volume_index].name:
                source = None  # free the previous volume before loading the next
                source = load_dataset_volume(config, plan.volume_index, device)
            bar.set_postfix_str(f"{plan.id} {source.name}")
            write_video(config, source, plan, out, bar.update)
            write_json(out / "manifest.json", build_manifest(config, out, plans, device))
    manifest = build_manifest(config, out, plans, device)
    write_json(out / "manifest.json", manifest)
    elapsed = time.perf_counter() - started
    rate = f", {len(todo) * config.frames_per_video / elapsed:.2f} frames/s" if todo else ""
    log(f"{out / 'manifest.json'}: {len(manifest['videos'])} of {len(plans)} videos, "
        f"{'complete' if manifest['complete'] else 'incomplete'} (rendered {len(todo)} in {_duration(elapsed)}{rate})")
    return manifest
