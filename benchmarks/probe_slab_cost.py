"""What depth slabs cost the ray caster: ``render(..., slabs=K)`` against ``slabs=0`` on the bench's orbits.

    python benchmarks/probe_slab_cost.py [--volumes CT_AVM,LIDC2,bonsai,MR_Gd] [--sizes 128,256] [--slabs 0,1,2,3]
                                         [--passes 4]

Each volume as ``volsr bench`` draws it (look, value range, start jitter), the frames of its 12-frame, 2° orbit
rendered with motion vectors to the previous camera at every size and slab count, the slab counts alternating frame
by frame so that machine noise hits them alike; prints the median ms of the frames after the first pass's (which
compile) and each count's ratio to the first. Edit the ray program (``volsr_core/render/stages.py``) and run it
again to price a change: the kernels compile anew (``tests/test_kernel_cache.py``).
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from volsr_core.apps.bench.scenes import load_bench_volume
from volsr_core.render import RayCaster
from volsr_core.scene.camera_paths import orbit_around

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"
SCENES = {"CT_AVM": "CT_AVM.nii.gz:CT-AAA:0,446", "LIDC2": "LIDC2.mha:CT-Bone:0,255",
          "bonsai": "bonsai.nii.gz:CT-Bone:auto", "MR_Gd": "MR_Gd.nii.gz:MR-Default:auto"}
FRAMES = 12


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volumes", default=",".join(SCENES))
    parser.add_argument("--sizes", default="128,256")
    parser.add_argument("--slabs", default="0,1,2,3")
    parser.add_argument("--passes", type=int, default=4)
    args = parser.parse_args()
    counts = [int(k) for k in args.slabs.split(",")]
    print("| volume | LR size | " + " | ".join(f"{k} slabs ms (ratio)" for k in counts) + " |")
    print("|---|---:|" + "---:|" * len(counts))
    for name in args.volumes.split(","):
        scene = load_bench_volume(str(DATA / SCENES[name]))
        caster = RayCaster(scene.volume, scene.transfer_function, start_jitter="ign")
        cameras = orbit_around(caster.visible_bounds(), FRAMES, 2.0, aspect=1.0)
        for size in (int(s) for s in args.sizes.split(",")):
            times: dict[int, list[float]] = {k: [] for k in counts}
            for _ in range(args.passes):
                for t in range(1, FRAMES):
                    for k in counts:
                        started = time.perf_counter()
                        caster.render(cameras[t], size, size, previous_camera=cameras[t - 1], seed=t, slabs=k)
                        times[k].append(1000.0 * (time.perf_counter() - started))
            ms = {k: statistics.median(v[FRAMES - 1:]) for k, v in times.items()}
            cells = " | ".join(f"{ms[k]:.2f} ({ms[k] / ms[counts[0]]:.3f})" for k in counts)
            print(f"| {name} | {size}² | {cells} |", flush=True)


if __name__ == "__main__":
    main()
