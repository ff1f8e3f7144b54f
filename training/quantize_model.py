"""Give a shipped U-Net an 8-bit ONNX file for the CPU: quantized, registered, and described in its model card.

    python training/quantize_model.py volsr-S-2x [--eval docs/eval/motion-2x-S-int8/eval.json] [--card-only]

Calibrates onnxruntime's static quantization (:func:`volsr_core.runtime.quantize.quantize_int8`) on the inputs the
upscaler gives the model on two orbits of the validation volume (the engine in the CT-Cardiac look, as the training
data's validation split has it; no benchmark volume): 8 frames of 2° at 512² and 8 of 5° at 1024², the first two of
each left out (no history yet). Refuses a copy whose output lies less than :data:`FIDELITY_DB` from the float32
file's on those inputs. Writes ``resources/models/NAME.int8.onnx`` (atomically), adds it to ``models.json``
(``files``/``sha256`` ``onnx_int8``, which ``model_file_to_run`` hands the CPU, with ``int8_op_types`` and
``int8_fidelity_db``) and writes the card's section
"8-bit file for the CPU": its fidelity and, with ``--eval`` (``volsr eval resources/models/NAME.int8.onnx --data
out/dataset_motion --split test``), its held-out numbers. ``--card-only`` writes that section for the file already
registered, without quantizing again (for the ``--eval`` of the file just made). ``ship_model.py`` replaces the
whole entry: a model shipped anew has no 8-bit file until this runs again.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from model_card_costs import replace_section
from ship_model import MODELS, REPO, metrics_table

CALIBRATION = REPO.parent / "shared" / "data" / "volumes" / "engine.nii.gz"
CALIBRATION_LOOK = "CT-Cardiac"
ORBITS = ((512, 2.0), (1024, 5.0))  # output size, degrees per frame
FRAMES, SKIPPED = 8, 2
FIDELITY_DB = 40.0
"""The least PSNR of the 8-bit file's output against the float32 file's on the calibration inputs. At shipping
(2026-12-01) S 2x's, every operator quantized, lay 45.5 dB from it; S 4x's 28.5 dB that way (M 4x's and S 8x's
under this too), and with the convolutions alone S 4x 45.8, M 4x 43.4, S 8x 49.1."""
OP_TYPES = (None, ("Conv",))
"""What is quantized, tried in turn until the copy keeps :data:`FIDELITY_DB`: every operator onnxruntime can (the
fewest float32 operators between the integer kernels), else the convolutions alone."""
SECTION = "## 8-bit file for the CPU"


def calibration_feeds(onnx_path: Path) -> list[dict[str, np.ndarray]]:
    """The upscaler's feeds of ``onnx_path`` on :data:`ORBITS` of the calibration volume."""
    from volsr_core.apps.bench.scenes import load_bench_volume
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.runtime.quantize import FeedRecorder
    from volsr_core.scene.camera_paths import orbit_around

    scene = load_bench_volume(f"{CALIBRATION}:{CALIBRATION_LOOK}")
    feeds: list[dict[str, np.ndarray]] = []
    for size, degrees in ORBITS:
        pipeline = Pipeline(scene.volume, scene.transfer_function, onnx_path, size=(size, size), threads=2)
        recorder = pipeline.upscaler.engine = FeedRecorder(pipeline.engine)
        for camera in orbit_around(pipeline.caster.visible_bounds(), FRAMES, degrees):
            pipeline.render(camera)
        feeds += recorder.feeds[SKIPPED:]
    return feeds


def fidelity_db(float_path: Path, int8_path: Path, feeds: list[dict[str, np.ndarray]]) -> float:
    """The PSNR (dB) of the 8-bit file's outputs, clipped to [0, 1], against the float32 file's, over ``feeds``."""
    from volsr_core.runtime.engines import OnnxEngine

    sessions = [OnnxEngine(path, providers=["CPUExecutionProvider"]).session for path in (float_path, int8_path)]
    errors = [np.mean((np.clip(sessions[1].run(None, feed)[0], 0, 1) - np.clip(sessions[0].run(None, feed)[0], 0, 1))
                      ** 2) for feed in feeds]
    return float(10.0 * np.log10(1.0 / max(float(np.mean(errors)), 1e-12)))


def card_section(entry: dict, eval_paths: list[Path]) -> list[str]:
    """The card's section on the 8-bit file of ``entry`` (its registry entry, which holds what was quantized and the
    fidelity measured)."""
    path = MODELS / entry["files"]["onnx_int8"]
    lines = [SECTION, "", f"`{path.name}` ({path.stat().st_size / 2**20:.2f} MiB; SHA-256 in `models.json`) is what "
             "hosts, `volsr upscale` and `volsr bench` run on the CPU (`model_file_to_run`); a GPU runs "
             f"`{entry['files']['onnx']}`. onnxruntime's static quantization (QDQ, int8 weights per output channel, "
             "uint8 activations; "
             + {("all",): "every operator it can", ("Conv",): "its convolutions alone"}.get(
                 tuple(entry["int8_op_types"]), "operators " + ", ".join(entry["int8_op_types"]))
             + " quantized, the clipped history input and what reads it float32), calibrated on "
             f"{len(ORBITS) * (FRAMES - SKIPPED)} of the upscaler's calls on orbits of the validation volume "
             f"(`{CALIBRATION.name}`, {CALIBRATION_LOOK}; " + ", ".join(f"{s}² at {d:g}°/frame" for s, d in ORBITS)
             + "): `python training/quantize_model.py " + entry["name"] + "`.", "",
             f"Its output lies {entry['int8_fidelity_db']:.1f} dB (PSNR) from the float32 file's on those calls.", ""]
    for eval_path in eval_paths:
        lines += metrics_table(eval_path)
    return lines


def main() -> None:
    from volsr_core.atomic import atomic_write
    from volsr_core.hashing import file_sha256
    from volsr_core.runtime.models import INT8_KIND
    from volsr_core.runtime.quantize import quantize_int8

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("name", help="a shipped model's name (models.json), a U-Net: volsr-S-2x")
    parser.add_argument("--eval", type=Path, action="append", default=[], help="eval.json of the 8-bit file")
    parser.add_argument("--card-only", action="store_true", help="the card section alone, for the file registered")
    args = parser.parse_args()
    registry_path = MODELS / "models.json"
    registry = json.loads(registry_path.read_text())
    entry = next((m for m in registry["models"] if m["name"] == args.name), None)
    if entry is None or entry["variant"] == "XS":
        raise SystemExit(f"{registry_path}: {args.name} is no shipped U-Net (XS runs in its own kernel)")
    float_path, int8_path = MODELS / entry["files"]["onnx"], MODELS / f"{args.name}.int8.onnx"
    if args.card_only:
        if file_sha256(int8_path) != entry["sha256"].get(INT8_KIND):
            raise SystemExit(f"{int8_path}: not the 8-bit file models.json registers; run without --card-only")
    else:
        feeds = calibration_feeds(float_path)
        for op_types in OP_TYPES:
            quantize_int8(float_path, int8_path, feeds, op_types)
            fidelity = fidelity_db(float_path, int8_path, feeds)
            print(f"{int8_path.name}, {op_types or 'every operator'} quantized: {fidelity:.1f} dB from the float32 "
                  "file's output")
            if fidelity >= FIDELITY_DB:
                break
        else:
            int8_path.unlink()
            raise SystemExit(f"{int8_path}: output under {FIDELITY_DB:g} dB from the float32 file's, however quantized")
        entry["int8_op_types"], entry["int8_fidelity_db"] = list(op_types or ["all"]), round(fidelity, 1)
        entry["files"][INT8_KIND], entry["sha256"][INT8_KIND] = int8_path.name, file_sha256(int8_path)
        with atomic_write(registry_path, "w") as fh:
            json.dump(registry, fh, indent=1)
            fh.write("\n")
        print(f"{int8_path.relative_to(REPO)}: {fidelity:.1f} dB from the float32 file's output, registered")
    card_path = MODELS / entry["files"]["card"]
    with atomic_write(card_path, "w") as fh:
        fh.write(replace_section(card_path.read_text(), card_section(entry, args.eval), SECTION))
    print(f"{card_path.relative_to(REPO)}: section {SECTION[3:]!r}")


if __name__ == "__main__":
    main()
