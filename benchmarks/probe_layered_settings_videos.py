"""The layered TAAU's settings at one scale, in one slab and two, against TAAU, on a dataset's stored videos.

    python benchmarks/probe_layered_settings_videos.py out/dataset_motion [--scale 2]   # about a minute on 2 cores

The layered TAAU's splat width (``sigma``, LR px) and history length (``cap_angle``) were chosen at 4x, where XS 4x
runs it (docs/temporal.md, "A shorter history"); at 2x its history under rotation holds a quarter of a frame's
weight and its splat half an HR pixel. This replays every video of a dataset made with ``slabs: 2``
(``volsr dataset training/configs/dataset_motion.yaml --out out/dataset_motion``) from its stored LR frames: TAAU
(as the TAAU method runs it, told each frame's pixels per voxel) and the layered TAAU as shipped and with each of
:data:`VARIANTS`, on the video's two depth slabs and on the two composited into one (what ``Pipeline`` runs for one
slab), and prints, per split and over the videos whose frames sample finely (TAAU's fine-sampling ramp), the mean
PSNR (dB) of frames 4 on against the stored truth, with the shipped XS filter of the scale on each estimate beside it.
"""
from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import h5py
import numpy as np
from probe_stretch_kernel import WARMUP, psnr
from tqdm import tqdm

from volsr_core.dataset.store import frame_pixels_per_voxel, read_json, view_rotations
from volsr_core.render.slabs import composited
from volsr_core.runtime.base_filter import filter_image
from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.models import model_file
from volsr_core.temporal.layered import LayeredUpsampler
from volsr_core.temporal.taau import TemporalUpsampler

VARIANTS = {"as shipped": {},
            "sigma 0.35": {"sigma": 0.35},
            "sigma 0.35, cap_angle 2/3": {"sigma": 0.35, "cap_angle": 2.0 / 3.0},
            "sigma 0.35, always clamped": {"sigma": 0.35, "clamp_rotating": "always"},
            "sigma 0.5": {"sigma": 0.5}}  # LayeredUpsampler settings, beside its defaults


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path, help="a dataset folder made with `slabs: 2`")
    parser.add_argument("--scale", type=int, default=2, choices=(2, 4), help="2 or 4: the scales XS has a model at")
    args = parser.parse_args()
    weights, bias = OnnxEngine(model_file("XS", args.scale, "onnx")).base_filter
    manifest, s = read_json(args.dataset / "manifest.json"), args.scale
    if manifest is None:
        parser.error(f"{args.dataset / 'manifest.json'}: missing or not JSON (make it with `volsr dataset`)")
    scores: dict[str, dict[str, list[tuple[float, float]]]] = defaultdict(lambda: defaultdict(list))
    for video in tqdm(manifest["videos"], desc="videos", unit="video"):
        with h5py.File(args.dataset / video["file"], "r") as h5:
            if f"lr{s}/slabs" not in h5:
                parser.error(f"{args.dataset / video['file']}: no depth slabs at {s}x "
                             f"(make the dataset with `slabs: 2`)")
            colour, motion, jitter, slabs = (h5[f"lr{s}/{k}"][()].astype(np.float32)
                                             for k in ("color", "motion", "jitter", "slabs"))
            depth = h5[f"lr{s}/motion_depth"][()].astype(np.float32)
            truth = h5["hr/color"][()].astype(np.float32)
            rotation = view_rotations(h5["cameras"][()])
        fineness = frame_pixels_per_voxel(video, colour.shape[1])
        fine = any(TemporalUpsampler(s).smoothing(p) > 0.0 for p in fineness if p is not None)
        groups = [video["split"]] + (["fine"] if fine else [])
        runs = {"TAAU": (TemporalUpsampler(s, side_outputs=False), None)}
        runs.update({f"layered, {k} slab{'s' * (k > 1)}, {name}": (LayeredUpsampler(s, **settings), k)
                     for k in (1, 2) for name, settings in VARIANTS.items()})
        for label, (upsampler, k) in runs.items():
            for t in range(len(colour)):
                if k is None:
                    image = upsampler(colour[t], motion[t], tuple(jitter[t]), depth[t], rotation[t], fineness[t])
                else:
                    frame_slabs = composited(slabs[t]) if k == 1 else slabs[t]
                    image = upsampler(frame_slabs, tuple(jitter[t]), (0.0, 0.0, 0.0), rotation[t], fineness[t])
                if t >= WARMUP:
                    score = (psnr(image, truth[t]), psnr(filter_image(image, weights, bias), truth[t]))
                    for group in groups:
                        scores[group][label].append(score)
    print(f"\n{args.dataset}, {s}x, frames {WARMUP} on: mean PSNR dB, the estimate / XS {s}x's filter on it\n")
    print("| estimate | " + " | ".join(scores) + " |\n|---|" + "---:|" * len(scores))
    for label in next(iter(scores.values())):  # the rows in the order they ran
        cells = [" / ".join(f"{v:.2f}" for v in np.mean(scores[group][label], axis=0)) for group in scores]
        print(f"| {label} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
