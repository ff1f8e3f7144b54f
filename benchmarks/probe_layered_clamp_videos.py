"""The layered TAAU's clamp under rotation, never against where frames sample finely (the default), on training videos.

    python benchmarks/probe_layered_clamp_videos.py training/configs/dataset_motion.yaml   # ~8 min, 2 cores

``LayeredUpsampler(clamp_rotating="fine")`` clamps the history while the view rotates on frames whose output samples
the volume finely (TAAU's fine-sampling ramp, from 1.75 output pixels a voxel); it was chosen on the bench's 1024²
orbits and the engine (docs/performance.md, "Off the bench"). This replays a dataset config's videos that have such
frames (their cameras, rendered here at the config's ``hr_size``, scale 4, 2 depth slabs, ray starts jittered as the
bench renders) through the layered TAAU with ``"never"`` and ``"fine"``, and prints per video the mean PSNR (dB) of
frames 4 on against the 16-spp truth, of the layered estimate and of XS 4x's shipped filter on it. A video with no
such frame gives the same images either way, so it is skipped.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from probe_stretch_kernel import WARMUP, psnr
from tqdm import tqdm

from volsr_core.dataset.config import read_config
from volsr_core.dataset.videos import camera_path, load_dataset_volume, plan_videos
from volsr_core.runtime.base_filter import filter_image
from volsr_core.runtime.engines import OnnxEngine
from volsr_core.runtime.methods import Taau
from volsr_core.temporal.ground_truth import supersampled_truth
from volsr_core.temporal.layered import LayeredUpsampler

SCALE, SLABS = 4, 2
MODEL = Path(__file__).resolve().parents[1] / "resources" / "models" / "volsr-XS-4x.onnx"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path, help="a dataset config, e.g. training/configs/dataset_motion.yaml")
    args = parser.parse_args()
    weights, bias = OnnxEngine(MODEL).base_filter  # XS 4x's filter, as the upscaler runs it
    config = read_config(args.config)
    width, height = config.hr_size
    print("| video | split | volume | output px a voxel | layered TAAU never / fine | XS 4x never / fine |")
    print("|---|---|---|---|---|---|")
    source = None
    for plan in plan_videos(config):
        if source is None or source[0] != plan.volume_index:
            source = (plan.volume_index, load_dataset_volume(config, plan.volume_index))
        volume = source[1]
        cameras = camera_path(config, volume, plan)
        ppv = [volume.caster.pixels_per_voxel(camera, height) for camera in cameras]  # per image height
        if LayeredUpsampler(SCALE).smoothing(max(ppv) / SCALE) == 0.0:
            continue
        truth = [supersampled_truth(volume.caster, camera, t, width, height) for t, camera in enumerate(cameras)
                 if t >= WARMUP]
        scores = {}
        for rule in ("never", "fine"):
            method = Taau(volume.caster, (width, height), SCALE, SLABS)
            method.upsampler = LayeredUpsampler(SCALE, clamp_rotating=rule)
            images = [method(camera).image for camera in tqdm(cameras, desc=f"{plan.id} {rule}", leave=False)]
            scored = list(zip(truth, images[WARMUP:]))
            scores[rule] = (np.mean([psnr(image, t) for t, image in scored]),
                            np.mean([psnr(filter_image(image, weights, bias), t) for t, image in scored]))
        (taau_never, xs_never), (taau_fine, xs_fine) = scores["never"], scores["fine"]
        print(f"| {plan.id} | {plan.split} | {volume.name} | {min(ppv):.2f}-{max(ppv):.2f} | "
              f"{taau_never:.2f} / {taau_fine:.2f} | {xs_never:.2f} / {xs_fine:.2f} |", flush=True)


if __name__ == "__main__":
    main()
