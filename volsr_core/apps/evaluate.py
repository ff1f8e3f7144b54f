"""``volsr eval``: the network against bilinear, bicubic and TAAU on the same frames of a dataset split.

The methods (``results["methods"]``, in :data:`METHODS` order): "bilinear" (the unjittered LR
render upscaled, what VTK shows; version-2 stores only), the jittered LR frame upscaled bilinearly
and bicubically, TAAU, for a network on the layered TAAU (``taau_slabs``) that TAAU's estimate
("layered TAAU", its base) and VolSR. Per video and frame t >= N (the frames the network can see N
previous frames for): PSNR and SSIM from scikit-image against the HR ground truth, and a temporal-stability
error: the mean absolute difference between the output's and the ground truth's frame-to-frame change after
backward-warping frame t-1 onto t with the (upsampled) motion vectors, over pixels whose
reprojection stays on screen. Lower is steadier; 0 means the output flickers exactly as the
ground truth changes. The baselines are :mod:`volsr_core.runtime.methods`' upscaling stages on the
dataset's LR frames (bilinear and bicubic on each frame; TAAU over each whole video from frame 0, as
it would live); the network gets its history from :class:`~volsr_core.sr.history.HistoryFeed` (fed
from frame 0: a TAAU-based network refines the same TAAU frames; a recurrent one runs from frame N
on, its first output without history).
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable

import h5py
import numpy as np
import torch

from volsr_core.atomic import atomic_write
from volsr_core.dataset.store import frame_pixels_per_voxel, view_rotations
from volsr_core.runtime.methods import ReducedSize, Taau
from volsr_core.sr.history import HistoryFeed
from volsr_core.sr.loader import SequenceDataset, slabs_mismatch
from volsr_core.sr.metrics import psnr_ssim_many
from volsr_core.sr.network import SuperResolutionNet
from volsr_core.temporal.resample import upscale_bilinear
from volsr_core.temporal.warp import backward_warp

# "bilinear": version-2 stores; "layered TAAU": the base of a network with taau_slabs
METHODS = ("bilinear", "bilinear, jittered", "bicubic, jittered", "TAAU", "layered TAAU", "VolSR")


def temporal_error(out_prev: np.ndarray, out: np.ndarray, gt_prev: np.ndarray, gt: np.ndarray,
                   hr_motion: np.ndarray) -> float:
    """Mean |(out_t - warp(out_t-1)) - (gt_t - warp(gt_t-1))| over pixels that stay on screen."""
    warped_out, valid = backward_warp(out_prev, hr_motion)
    warped_gt, _ = backward_warp(gt_prev, hr_motion)
    diff = np.abs((out - warped_out) - (gt - warped_gt)).mean(axis=-1)
    return float(diff[valid].mean()) if valid.any() else float("nan")


class VideoFrames:
    """One video's LR frames at one scale (jittered colour, motion, jitter, motion depth, and the unjittered
    ``centred`` colour when the store has it: version 2; the depth slabs when it has them), view rotations,
    pixels per voxel (None unless the JSON ``entry`` records ``voxel_size``) and HR ground truth, from its store."""

    def __init__(self, path: Path, scale: int, entry: dict[str, Any] | None = None):
        with h5py.File(path, "r") as h5:
            self.lr = h5[f"lr{scale}/color"][()].astype(np.float32)
            self.motion = h5[f"lr{scale}/motion"][()].astype(np.float32)
            self.jitter = h5[f"lr{scale}/jitter"][()].astype(np.float32)
            depth = f"lr{scale}/motion_depth" if f"lr{scale}/motion_depth" in h5 else f"lr{scale}/depth"
            self.depth = h5[depth][()].astype(np.float32)
            self.centred = h5[f"lr{scale}/centred"][()].astype(np.float32) if f"lr{scale}/centred" in h5 else None
            self.slabs = h5[f"lr{scale}/slabs"][()].astype(np.float32) if f"lr{scale}/slabs" in h5 else None
            self.rotation = view_rotations(h5["cameras"][()])
            self.hr = h5["hr/color"][()].astype(np.float32)
        self.pixels_per_voxel = (frame_pixels_per_voxel(entry, self.lr.shape[1]) if entry is not None
                                 else [None] * len(self.lr))

    def taau_inputs(self, t: int) -> tuple:
        """Frame t as TAAU takes it: colour, motion, jitter, depth, rotation, pixels per voxel."""
        return (self.lr[t], self.motion[t], tuple(self.jitter[t]), self.depth[t], float(self.rotation[t]),
                self.pixels_per_voxel[t])

    def hr_motion(self, t: int, scale: int) -> np.ndarray:
        return upscale_bilinear(self.motion[t], scale) * scale


def _baselines(video: VideoFrames, scale: int) -> dict[str, Callable[[int], np.ndarray]]:
    """Each baseline's frame t: the methods' upscaling stages on the stored LR frames. "bilinear" upscales
    the unjittered LR render (what VTK's ImageSampleDistance shows) when the store has it; the jittered
    frames' bilinear and bicubic upscales are the super-resolution papers' baselines."""
    h, w = video.hr.shape[1:3]
    bilinear, bicubic = (ReducedSize(None, (w, h), scale, kind) for kind in ("bilinear", "bicubic"))
    taau = Taau(None, (w, h), scale)
    taau_frames = [taau.upscale(*video.taau_inputs(t)) for t in range(len(video.lr))]
    methods = {"bilinear, jittered": lambda t: bilinear.upscale(video.lr[t]),
               "bicubic, jittered": lambda t: bicubic.upscale(video.lr[t]),
               "TAAU": lambda t: taau_frames[t]}
    if video.centred is not None:
        methods["bilinear"] = lambda t: bilinear.upscale(video.centred[t])
    return methods


class OnnxNetwork:
    """An ONNX model file behind the calls :func:`evaluate` makes of a SuperResolutionNet (``config``, ``eval()``,
    torch tensors in and out), run by onnxruntime on the CPU: the file hosts run, an 8-bit one among them."""

    def __init__(self, path: str | os.PathLike):
        from volsr_core.runtime.engines import OnnxEngine

        self.engine = OnnxEngine(path, providers=["CPUExecutionProvider"])
        self.config = self.engine.config

    def eval(self) -> "OnnxNetwork":
        return self

    def __call__(self, lr: torch.Tensor, motion: torch.Tensor, jitter: torch.Tensor,
                 history: torch.Tensor | None = None) -> torch.Tensor:
        return torch.from_numpy(self.engine(lr.numpy(), motion.numpy(), jitter.numpy(),
                                            None if history is None else history.numpy()))


@torch.no_grad()
def evaluate(model: SuperResolutionNet | OnnxNetwork, data_root: str | os.PathLike, split: str = "test",
             progress: bool = True) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Metrics per video, method and frame, plus per-method means over all evaluated frames.

    Also returns a showcase: the middle evaluated frame of the first video, per method and "ground
    truth", for the crop grid.
    """
    cfg = model.config
    model.eval()
    data = SequenceDataset(data_root, split, cfg.scale, cfg.previous_frames, crop=None, features=cfg.features,
                           augment=False)
    by_video: dict[int, list[int]] = {}
    for index, (video_index, _) in enumerate(data.samples):
        by_video.setdefault(video_index, []).append(index)
    results: dict[str, Any] = {"split": split, "scale": cfg.scale, "previous_frames": cfg.previous_frames,
                               "videos": {}}
    showcase: dict[str, np.ndarray] = {}
    iterator = by_video.items()
    if progress:
        from tqdm import tqdm
        iterator = tqdm(list(iterator), desc=f"eval {split}", unit="video")
    for video_index, indices in iterator:
        meta = data.videos[video_index]
        frames = VideoFrames(data.root / meta["file"], cfg.scale, meta)
        have = 0 if frames.slabs is None else frames.slabs.shape[1]
        if cfg.taau_slabs and have != cfg.taau_slabs:
            raise slabs_mismatch(data.root / meta["file"], have, cfg.taau_slabs, cfg.scale)
        methods = _baselines(frames, cfg.scale)
        network_out: dict[int, np.ndarray] = {}
        feed = HistoryFeed(cfg)
        samples = {data.samples[index][1]: index for index in indices}  # frame t -> sample
        layered: dict[int, np.ndarray] = {}
        for t in range(len(frames.lr)):
            history = feed(*frames.taau_inputs(t), slabs=None if frames.slabs is None else frames.slabs[t])
            if feed.slabs:
                layered[t] = np.clip(history, 0.0, 1.0)
            if t not in samples:  # before frame N: only the history follows the video
                continue
            item = data[samples[t]]
            inputs = [item[k][None] for k in ("lr", "motion", "jitter")]
            if cfg.takes_history:
                if history is not None:
                    history = torch.from_numpy(np.ascontiguousarray(history.transpose(2, 0, 1)))[None]
                out = model(*inputs, history)
            else:
                out = model(*inputs)
            network_out[t] = np.clip(out[0].permute(1, 2, 0).numpy(), 0.0, 1.0)
            feed.keep(out[0].permute(1, 2, 0).numpy())
        methods["VolSR"] = network_out.__getitem__
        if layered:
            methods["layered TAAU"] = layered.__getitem__
        names = [name for name in METHODS if name in methods and all(name in v for v in results["videos"].values())]
        results["methods"] = names
        ts = sorted(network_out)
        video: dict[str, Any] = {"volume": meta["volume"], "frames": ts}
        for name in names:
            outputs = {t: methods[name](t) for t in ts}
            scores = psnr_ssim_many([(outputs[t], frames.hr[t]) for t in ts], channel_axis=-1)
            temporal = [temporal_error(outputs[a], outputs[b], frames.hr[a], frames.hr[b],
                                       frames.hr_motion(b, cfg.scale)) for a, b in zip(ts, ts[1:])]
            video[name] = {"psnr": [s[0] for s in scores], "ssim": [s[1] for s in scores], "temporal": temporal}
        results["videos"][meta["id"]] = video
        if not showcase:
            middle = ts[len(ts) // 2]
            showcase = {"ground truth": frames.hr[middle], **{name: methods[name](middle) for name in names}}
    results["overall"] = {name: {metric: _mean([v for video in results["videos"].values() for v in video[name][metric]])
                                 for metric in ("psnr", "ssim", "temporal")} for name in results["methods"]}
    return results, showcase


def crop_grid(showcase: dict[str, np.ndarray], crop: int = 64, zoom: int = 3) -> np.ndarray:
    """The ``crop``-pixel square with the most detail in the ground truth, zoomed, one labelled panel per image."""
    from PIL import Image, ImageDraw

    gt = showcase["ground truth"]
    energy = np.abs(np.diff(gt.mean(-1), axis=0))[:, :-1] + np.abs(np.diff(gt.mean(-1), axis=1))[:-1]
    crop = min(crop, *energy.shape)
    sums = energy.cumsum(0).cumsum(1)
    window = sums[crop - 1:, crop - 1:].copy()
    window[1:] -= sums[:-crop, crop - 1:]
    window[:, 1:] -= sums[crop - 1:, :-crop]
    window[1:, 1:] += sums[:-crop, :-crop]
    y, x = np.unravel_index(np.argmax(window), window.shape)
    panels = []
    for name, image in showcase.items():
        patch = np.clip(image[y:y + crop, x:x + crop], 0, 1).repeat(zoom, 0).repeat(zoom, 1)
        panel = Image.fromarray((patch * 255).round().astype(np.uint8))
        ImageDraw.Draw(panel).text((4, 4), name, fill=(255, 255, 0))
        panels.append(np.asarray(panel))
    return np.concatenate(panels, axis=1)


def _mean(values: list[float]) -> float:
    finite = [v for v in values if np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


def markdown_table(results: dict[str, Any]) -> str:
    """Per-method means, overall and per video, as a markdown table."""
    lines = [f"Split `{results['split']}`, {results['scale']}x, {results['previous_frames']} previous frames. "
             "PSNR/SSIM: higher is better; temporal error: lower is better.", "",
             "| video | volume | method | PSNR dB | SSIM | temporal error |", "|---|---|---|---|---|---|"]
    for name in results["methods"]:
        o = results["overall"][name]
        lines.append(f"| **all** | | {name} | **{o['psnr']:.2f}** | **{o['ssim']:.4f}** | **{o['temporal']:.4f}** |")
    for vid, video in results["videos"].items():
        for name in results["methods"]:
            m = video[name]
            lines.append(f"| {vid} | {video['volume']} | {name} | {_mean(m['psnr']):.2f} | {_mean(m['ssim']):.4f} "
                         f"| {_mean(m['temporal']):.4f} |")
    return "\n".join(lines) + "\n"


def write_report(results: dict[str, Any], showcase: dict[str, np.ndarray], out_dir: str | os.PathLike) -> list[Path]:
    """eval.json, eval.md, the plots (PSNR per frame, bars per method) and crops.png in ``out_dir``."""
    from PIL import Image

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_write(out / "eval.json", "w") as fh:
        json.dump(results, fh, indent=1)
    with atomic_write(out / "eval.md", "w") as fh:
        fh.write(markdown_table(results))
    fig, ax = plt.subplots(figsize=(8, 4))
    offset = 0
    for vid, video in results["videos"].items():
        x = np.arange(offset, offset + len(video["frames"]))
        for i, name in enumerate(results["methods"]):
            ax.plot(x, video[name]["psnr"], color=f"C{i}", label=name if offset == 0 else None)
        offset += len(video["frames"]) + 2
    ax.set_xlabel("frame (videos one after another)")
    ax.set_ylabel("PSNR (dB)")
    ax.legend()
    fig.tight_layout()
    _save(fig, out / "psnr_per_frame.png")
    fig, axes = plt.subplots(1, 3, figsize=(10, 3.2))
    for ax, metric in zip(axes, ("psnr", "ssim", "temporal")):
        names = results["methods"]
        values = [results["overall"][m][metric] for m in names]
        ax.bar(names, values, color=[f"C{i}" for i in range(len(names))])
        ax.set_title({"psnr": "PSNR (dB)", "ssim": "SSIM", "temporal": "temporal error"}[metric])
        ax.tick_params(axis="x", rotation=30)
        if metric == "psnr":
            ax.set_ylim(min(values) - 2, max(values) + 1)
    fig.tight_layout()
    _save(fig, out / "methods.png")
    with atomic_write(out / "crops.png") as fh:
        Image.fromarray(crop_grid(showcase)).save(fh, format="PNG")
    return [out / n for n in ("eval.json", "eval.md", "psnr_per_frame.png", "methods.png", "crops.png")]


def _save(fig, path: Path) -> None:
    import matplotlib.pyplot as plt

    with atomic_write(path) as fh:
        fig.savefig(fh, format="png", dpi=120)
    plt.close(fig)
