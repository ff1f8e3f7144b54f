"""The seed paper's three studies on our data, trained and evaluated in one go; writes docs/ablations.md.

    python training/ablations.py [--steps 1500] [--doc docs/ablations.md]

Needs the datasets of training/configs/dataset_default.yaml (out/dataset_default),
training/configs/dataset_scales.yaml (out/dataset_scales) and training/configs/dataset_finetune.yaml
(out/dataset_finetune). Every run starts from
training/configs/ablation_base.yaml and changes only what its study varies; runs land in
runs/ablations/NAME and resume where they stopped (a finished run is not trained again).
Each is scored by ``evaluate`` on its dataset's test split, with bilinear, bicubic and TAAU on
the same frames.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT, SCALES = REPO / "out" / "dataset_default", REPO / "out" / "dataset_scales"
SOFT = REPO / "out" / "dataset_finetune"  # + semi-transparent looks: does RGBA at max alpha add more there?
ALL_FEATURES, NO_RGBA = ["color", "depth", "max_rgba"], ["color", "depth"]

# study -> (run name, dataset, scale, previous frames, features), as the paper's tables
STUDIES = {
    "RGBA at max alpha, 8x (paper: +1.0 dB with it)": [
        ("rgba_8x_with", DEFAULT, 8, 2, ALL_FEATURES), ("rgba_8x_without", DEFAULT, 8, 2, NO_RGBA),
        ("rgba_8x_soft_with", SOFT, 8, 2, ALL_FEATURES), ("rgba_8x_soft_without", SOFT, 8, 2, NO_RGBA)],
    "previous frames N, 4x (paper: 39.35 / 39.94 / 40.49 dB for N = 1 / 2 / 3)": [
        ("frames_4x_n1", DEFAULT, 4, 1, ALL_FEATURES), ("frames_4x_n2", DEFAULT, 4, 2, ALL_FEATURES),
        ("frames_4x_n3", DEFAULT, 4, 3, ALL_FEATURES)],
    "scale (paper: 42.37 / 37.92 / 33.65 dB at 4x / 8x / 16x)": [
        ("scale_4x", SCALES, 4, 2, ALL_FEATURES), ("scale_8x", SCALES, 8, 2, ALL_FEATURES),
        ("scale_16x", SCALES, 16, 2, ALL_FEATURES)],
}


def run_one(name: str, data: Path, scale: int, previous: int, features: list[str], steps: int) -> dict:
    """Train (or resume) one run and evaluate its last weights on the test split; cached in eval.json."""
    from volsr_core.sr.checkpoint import load_model
    from volsr_core.sr.config import load_training_config
    from volsr_core.apps.evaluate import evaluate, write_report
    from volsr_core.sr.training import Trainer

    out = REPO / "runs" / "ablations" / name
    config = load_training_config(REPO / "training" / "configs" / "ablation_base.yaml").updated(
        {"out": str(out), "data": {"root": str(data), "scale": scale, "previous_frames": previous, "features": features},
         "train": {"steps": steps}})
    report = out / "eval" / "eval.json"
    if report.exists() and json.loads(report.read_text()).get("steps") == steps:
        return json.loads(report.read_text())
    Trainer(config).run()
    results, showcase = evaluate(load_model(out / "checkpoints" / "last.pt"), data, "test")
    results["steps"] = steps
    write_report(results, showcase, out / "eval")
    return results


def table(rows: list[tuple[str, int, int, list[str], dict]]) -> list[str]:
    lines = ["| run | scale | N | features | VolSR PSNR dB | SSIM | temporal | TAAU PSNR | bicubic PSNR |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, scale, previous, features, results in rows:
        o = results["overall"]
        lines.append(f"| {name} | {scale}x | {previous} | {'+'.join(features)} | **{o['VolSR']['psnr']:.2f}** | "
                     f"{o['VolSR']['ssim']:.4f} | {o['VolSR']['temporal']:.4f} | {o['TAAU']['psnr']:.2f} | "
                     f"{o['bicubic']['psnr']:.2f} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=1500, help="training steps per run [1500]")
    parser.add_argument("--doc", type=Path, default=REPO / "docs" / "ablations.md")
    args = parser.parse_args()
    sections = []
    for study, runs in STUDIES.items():
        rows = []
        for name, data, scale, previous, features in runs:
            rows.append((name, scale, previous, features, run_one(name, data, scale, previous, features, args.steps)))
        sections.append((study, rows))
    write_doc(args.doc, sections, args.steps)


def write_doc(path: Path, sections: list, steps: int) -> None:
    from volsr_core.atomic import atomic_write

    lines = ["# The paper's three studies on VolSR's data", "",
             "Made by `python training/ablations.py --steps " f"{steps}` (after `volsr dataset "
             "training/configs/dataset_default.yaml --out out/dataset_default`, `volsr dataset "
             "training/configs/dataset_scales.yaml --out out/dataset_scales` and, for the `soft` runs, the "
             "default dataset plus semi-transparent looks: `cp -r out/dataset_default out/dataset_finetune; "
             "volsr dataset training/configs/dataset_finetune.yaml --out out/dataset_finetune`), on the 2-core "
             "CPU: the paper's "
             "non-recurrent network, variant S, "
             f"{steps} steps of batch 8 and 64-pixel crops per run (training/configs/ablation_base.yaml), each "
             "scored on its dataset's test split (3 videos of 24 frames at 256²; 9 for the `soft` runs). Short "
             "runs: the "
             "directions are what to read, not the absolute numbers. What they say, and where they differ "
             "from the paper: [network.md](network.md#the-papers-three-studies).", ""]
    for study, rows in sections:
        lines += [f"## {study}", ""] + table(rows) + [""]
    with atomic_write(path, "w") as fh:
        fh.write("\n".join(lines))


if __name__ == "__main__":
    main()
