"""``volsr bench`` on a lent GPU: the CUDA ray caster, the shipped models' .pt files on torch CUDA.

    python benchmarks/device/gpu_bench.py pack DIR            # here: the four bench volumes as .npz records
    python benchmarks/device/gpu_bench.py run OUT 1024/2,512/2 [CT_AVM,LIDC2,bonsai,MR_Gd] [--volumes DIR]

The lent machine (the ``device`` tool, docs/performance-gpu.md) has torch, numba-cuda and onnxruntime
(CPU provider only) but not SimpleITK or pydicom: ``pack`` writes each volume's ``VolumeRecord`` as
``<file name>.npz`` (voxels, spacing, origin, direction; lossless), and ``run`` reads those in place of the
files, so rows carry the same names as the CPU runs'. Models: the .pt files, the U-Nets on torch CUDA
(ONNX would run them on the CPU provider there), XS in the CPU kernel (from either file since 2026-11-26).
``run`` writes ``OUT/bench_<size>_<degrees>.json`` after each volume, so a run cut short keeps what it
finished; ``bench.md`` and ``bench.png`` are made from it afterwards
(``volsr_core.apps.bench.report.write_outputs``). ``benchmarks/device/run.sh`` is the device command.
"""
from __future__ import annotations

import importlib.util
import json
import sys
import time
import types
from pathlib import Path

import numpy as np

if importlib.util.find_spec("SimpleITK") is None:  # only the .npz records are read on the device
    sys.modules["SimpleITK"] = types.ModuleType("SimpleITK")

from volsr_core.apps.bench import run  # noqa: E402
from volsr_core.io.record import VolumeRecord  # noqa: E402
from volsr_core.scene import Volume  # noqa: E402

SCENES = {"CT_AVM": "CT_AVM.nii.gz:CT-AAA:0,446", "LIDC2": "LIDC2.mha:CT-Bone:0,255",
          "bonsai": "bonsai.nii.gz:CT-Bone", "MR_Gd": "MR_Gd.nii.gz:MR-Default"}
MODELS = (("XS", 2), ("S", 2), ("XS", 4), ("S", 4), ("M", 4), ("S", 8))


def pack(folder: Path, source: Path = Path("../shared/data/volumes")) -> None:
    """Each bench volume's record as ``folder/<file name>.npz``, voxels in the smallest integer type that holds them
    exactly."""
    from volsr_core.io import read_volume

    folder.mkdir(parents=True, exist_ok=True)
    for spec in SCENES.values():
        name = spec.split(":")[0]
        record = read_volume(source / name)
        voxels = record.array
        for dtype in (np.uint8, np.int16, np.uint16):
            if np.array_equal(voxels.astype(dtype).astype(np.float32), voxels):
                voxels = voxels.astype(dtype)
                break
        np.savez_compressed(folder / f"{name}.npz", array=voxels, spacing=record.spacing, origin=record.origin,
                            direction=record.direction, modality=record.modality, units=record.units)


def read_packed(folder: Path):
    """``Volume.load`` for packed records: the file name picks ``folder/<name>.npz``."""
    def load(cls, path, series_uid=None, resample=False):
        z = np.load(folder / f"{Path(path).name}.npz")
        return cls.from_record(VolumeRecord(
            array=z["array"].astype(np.float32), spacing=tuple(z["spacing"]), origin=tuple(z["origin"]),
            direction=z["direction"], modality=str(z["modality"]), units=str(z["units"]), source=str(path)))
    return classmethod(load)


def bench(out: Path, runs: list[tuple[int, float]], names: list[str], device: str = "cuda") -> None:
    from importlib.resources import files

    models = Path(str(files("volsr_core.resources") / "models"))
    specs = [run.ModelSpec(models / f"volsr-{v}-{s}x.pt", v, s) for v, s in MODELS]
    run.find_models = lambda folder, variants, scales: [m for m in specs if m.scale in scales]
    out.mkdir(parents=True, exist_ok=True)
    for size, degrees in runs:
        rows, start = [], time.time()
        for name in names:
            # no stretched rows (stretches=(1,)): on a GPU the step after the render that a stretch saves costs
            # little, and five rows more per volume would not fit the lease's minutes (docs/performance-gpu.md)
            results = run.run_benchmark([SCENES[name]], (size, size), degrees=degrees, device=device,
                                        models_dir="shipped .pt", stretches=(1,))
            rows += results["rows"]
            results["rows"], results["targets"] = rows, run.check_targets(rows)
            results["settings"]["wall_s"] = round(time.time() - start, 1)
            (out / f"bench_{size}_{degrees:g}.json").write_text(json.dumps(results, indent=1))
            margins = results["targets"][rows[-1]["scene"]]["above_bilinear"]["points"]
            print(f"== {size}² {degrees:g}° {name}: {time.time() - start:.0f} s; dB from the curve:",
                  ", ".join(f"{p['label'][6:]} {p['margin_db']:+.2f}" for p in margins), flush=True)


def main(argv: list[str]) -> None:
    if argv[0] == "pack":
        pack(Path(argv[1]))
        return
    volumes = Path(argv[argv.index("--volumes") + 1]) if "--volumes" in argv else Path(__file__).parent / "volumes"
    Volume.load = read_packed(volumes)
    positional = [a for a in argv[1:] if not a.startswith("--") and a != str(volumes)]
    runs = [(int(s), float(d)) for s, d in (r.split("/") for r in positional[1].split(","))]
    names = positional[2].split(",") if len(positional) > 2 else list(SCENES)
    bench(Path(positional[0]), runs, names, "cpu" if "--cpu" in argv else "cuda")


if __name__ == "__main__":
    main(sys.argv[1:])
