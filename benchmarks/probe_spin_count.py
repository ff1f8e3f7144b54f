"""How long numba's idle OpenMP threads spin, and what it costs the methods of ``volsr bench``: the same small bench
run in fresh processes under each ``GOMP_SPINCOUNT`` (libgomp reads it when it loads), alternating, round after round.

    python benchmarks/probe_spin_count.py [--volume CT_AVM.nii.gz:CT-AAA:0,446] [--size 512]
                                          [--spincounts 300000,100000,10000,0] [--rounds 3] [--out out/probe_spin]

libgomp's workers wait for the next parallel region by spinning ``GOMP_SPINCOUNT`` times on a ``pause`` instruction
before they sleep (300,000 unless set; 0 under ``OMP_WAIT_POLICY=PASSIVE``): about 7.7 ms on this project's Xeon (a
``pause`` there takes about 25 ns), a core taken from whatever runs after a numba kernel, onnxruntime's U-Nets among
them; VolSR sets 100,000 unless the process has its own (``volsr_core/__init__.py``). Each run is ``volsr bench`` on
one volume (TAAU and VolSR XS and S at 2x and 4x, native 1 spp and 1/2 and 1/4 size + bilinear, two timing passes).
Prints, per method, the median over the rounds of its median ms after the LR render and of its LR render, under each
setting, and each setting's ratio to the first.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "out"  # the repository's out/, whatever the working directory
DATA = Path(os.environ.get("VOLSR_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def bench_once(volume: str, size: int, spincount: str, out: Path) -> list[dict]:
    """One ``volsr bench`` in a fresh process under ``GOMP_SPINCOUNT=spincount``; its rows."""
    env = dict(os.environ, GOMP_SPINCOUNT=spincount)
    env.pop("OMP_WAIT_POLICY", None)
    command = [sys.executable, "-m", "volsr_core.cli", "bench", volume, "--size", str(size), "--out", str(out),
               "--spp", "1", "--factors", "2,4", "--scales", "2,4", "--stretch", "1", "--variants", "XS,S",
               "--timing-passes", "2"]
    subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL)
    return json.loads((out / "bench.json").read_text(encoding="utf-8"))["rows"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--volume", default="CT_AVM.nii.gz:CT-AAA:0,446", help="a shared volume[:preset[:range]]")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--spincounts", default="300000,100000,10000,0",
                        help="GOMP_SPINCOUNT values, the first the one the others are compared with")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=OUT / "probe_spin")
    args = parser.parse_args()
    settings = args.spincounts.split(",")
    volume = args.volume if Path(args.volume.split(":")[0]).exists() else str(DATA / "volumes" / args.volume)
    runs: dict[str, list[list[dict]]] = {s: [] for s in settings}
    for round_ in range(args.rounds):
        for setting in settings if round_ % 2 == 0 else reversed(settings):
            runs[setting].append(bench_once(volume, args.size, setting, args.out / f"{setting}-{round_}"))
            print(f"round {round_ + 1}/{args.rounds}, GOMP_SPINCOUNT {setting}: done", file=sys.stderr)
    labels = [r["label"] for r in runs[settings[0]][0] if r["method"] != "native" or r["spp"] == 1]
    print(f"{args.volume}, {args.size}², median of {args.rounds} runs a setting (GOMP_SPINCOUNT "
          + " / ".join(settings) + ")\n")
    print("| method | ms after the LR render | ratio | LR render ms | ratio |\n|---|---:|---:|---:|---:|")
    for label in labels:
        after, render = [], []
        for setting in settings:
            rows = [next(r for r in run if r["label"] == label) for run in runs[setting]]
            after.append(statistics.median(r["ms_network"] for r in rows))
            render.append(statistics.median(r["ms_render"] for r in rows))

        def ratios(values: list[float]) -> str:
            return " / ".join("-" if not values[0] else f"{v / values[0]:.2f}" for v in values[1:])
        print(f"| {label} | {' / '.join(f'{v:.1f}' for v in after)} | {ratios(after)} | "
              f"{' / '.join(f'{v:.1f}' for v in render)} | {ratios(render)} |")


if __name__ == "__main__":
    main()
