"""Training-data generation speed: frames per second of `volsr dataset` at a config's settings.

Renders the first ``--videos-per-volume`` videos of every volume exactly as the generator does
(camera path, HR ground truth, LR buffers at every scale, the HDF5 store with gzip, the JSON
entry) into a temporary folder, and reports frames per second per volume and overall, and the
projected time of the whole dataset (each volume's frames at its own measured rate).

    python benchmarks/bench_dataset.py [--config training/configs/dataset_default.yaml]
                                       [--videos-per-volume 1] [--device cpu]
                                       [--out benchmarks/results/dataset.json]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from volsr_core.atomic import atomic_write
from volsr_core.dataset.config import read_config
from volsr_core.dataset.videos import load_dataset_volume, plan_videos, write_video

REPO = Path(__file__).resolve().parents[1]


def bench_volume(config, plans, device: str, folder: Path) -> dict:
    """Render ``plans`` (videos of one volume) into ``folder``; time the rendering and writing."""
    source = load_dataset_volume(config, plans[0].volume_index, device)
    source.caster.render(source.pool[0], 8, 8)  # compile (or load) the renderer outside the timing
    started = time.perf_counter()
    for plan in plans:
        write_video(config, source, plan, folder)
    seconds = time.perf_counter() - started
    frames = len(plans) * config.frames_per_video
    return {"volume": source.name, "videos": len(plans), "frames": frames, "seconds": round(seconds, 2),
            "fps": round(frames / seconds, 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", default=str(REPO / "training" / "configs" / "dataset_default.yaml"))
    parser.add_argument("--videos-per-volume", type=int, default=1)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "dataset.json"))
    args = parser.parse_args()

    config = read_config(args.config)
    plans = plan_videos(config)
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "videos").mkdir()
        for vi, spec in enumerate(config.volumes):
            mine = [p for p in plans if p.volume_index == vi][:args.videos_per_volume]
            results.append(bench_volume(config, mine, args.device, Path(tmp)))
            r = results[-1]
            print(f"{r['volume']:>10}: {r['frames']} frames in {r['seconds']:.1f} s = {r['fps']:.3f} frames/s")
    frames = sum(r["frames"] for r in results)
    fps = frames / sum(r["seconds"] for r in results)
    projected = sum(spec.videos * config.frames_per_video / r["fps"] for spec, r in zip(config.volumes, results))
    total_frames = sum(spec.videos for spec in config.volumes) * config.frames_per_video
    print(f"overall: {fps:.3f} frames/s; the whole dataset ({total_frames} frames) projected at "
          f"{projected / 60:.1f} min on {args.device} ({os.cpu_count()} CPU cores)")
    report = {"config": os.path.relpath(args.config, REPO), "device": args.device, "cpu_count": os.cpu_count(),
              "machine": platform.processor() or platform.machine(), "volumes": results, "fps": round(fps, 4),
              "dataset_frames": total_frames, "projected_minutes": round(projected / 60, 1)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(args.out, "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1)
        fh.write("\n")


if __name__ == "__main__":
    main()
