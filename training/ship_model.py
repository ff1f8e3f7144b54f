"""Ship a trained model: weights-only .pt + ONNX in resources/models, the registry entry and a model card.

    python training/ship_model.py runs/s4x/best.pt --name volsr-S-4x --variant S \\
        --config training/configs/train_s4x.yaml --eval docs/eval/heldout-4x/eval.json \\
        --eval docs/eval/test-4x/eval.json --card-notes "..."

Writes resources/models/NAME.pt (``{"format": "volsr-model", "network", "state_dict"}``, loads
with ``torch.load(weights_only=True)``), NAME.onnx (dynamic height and width), NAME.md (the
card) and updates models.json with both files' SHA-256, which the runtime checks before use.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "resources" / "models"
LIMIT_BYTES = 10 * 1024 * 1024
RISK = "the network invents plausible detail that was not rendered"
RISK_XS = ("the filter sharpens what TAAU made (it invents no structure, but it can ring along edges and lift "
           "noise)")
TAAU_BASED = "TAAU-based (refines the TAAU estimate of each frame; the upscaler runs TAAU before it), "
LAYERED = ("on the layered TAAU (refines its estimate of each frame rendered in {} depth slabs, one history per slab; "
           "the upscaler runs it before), ")


def metrics_table(path: Path) -> list[str]:
    results = json.loads(path.read_text())
    lines = [f"`{path.resolve().relative_to(REPO).as_posix()}` ({results['split']} split, {results['scale']}x, "
             f"{len(results['videos'])} videos):", "",
             "| method | PSNR dB | SSIM | temporal error (lower is steadier) |", "|---|---|---|---|"]
    for method, o in results["overall"].items():
        lines.append(f"| {method} | {o['psnr']:.2f} | {o['ssim']:.4f} | {o['temporal']:.4f} |")
    return lines + [""]


def main() -> None:
    from volsr_core.atomic import atomic_write
    from volsr_core.hashing import file_sha256
    from volsr_core.runtime.export import OPSET, export_onnx
    from volsr_core.sr.checkpoint import load_model, save_checkpoint
    from volsr_core.sr.network_config import VARIANTS

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--name", required=True)
    parser.add_argument("--variant", required=True, choices=VARIANTS)
    parser.add_argument("--config", type=Path, required=True, help="the training config it was trained with")
    parser.add_argument("--eval", type=Path, action="append", default=[], help="eval.json files for the card")
    parser.add_argument("--card-notes", default="", help="markdown paragraph: data, time, hardware, quality bar")
    args = parser.parse_args()

    model = load_model(args.checkpoint)
    MODELS.mkdir(parents=True, exist_ok=True)
    pt, onnx_path = MODELS / f"{args.name}.pt", MODELS / f"{args.name}.onnx"
    save_checkpoint(pt, model, extra={"name": args.name, "variant": args.variant})
    export_onnx(model, onnx_path)
    for path in (pt, onnx_path):
        if path.stat().st_size > LIMIT_BYTES:
            raise SystemExit(f"{path}: {path.stat().st_size / 2**20:.1f} MiB, over the 10 MiB limit")
    cfg = model.config
    entry = {"name": args.name, "variant": args.variant, "scale": cfg.scale, "previous_frames": cfg.previous_frames,
             "recurrent": cfg.recurrent, "taau_base": cfg.taau_base, "taau_aux": cfg.taau_aux,
             **({"taau_slabs": cfg.taau_slabs} if cfg.taau_slabs else {}), "features": list(cfg.features),
             "files": {"pt": pt.name, "onnx": onnx_path.name, "card": f"{args.name}.md"},
             "sha256": {"pt": file_sha256(pt), "onnx": file_sha256(onnx_path)},
             "parameters": sum(p.numel() for p in model.parameters())}
    registry_path = MODELS / "models.json"
    registry = json.loads(registry_path.read_text()) if registry_path.exists() else {"models": []}
    registry["models"] = [m for m in registry["models"] if m["name"] != args.name] + [entry]
    registry["models"].sort(key=lambda m: (m["scale"], m["variant"]))
    with atomic_write(registry_path, "w") as fh:
        json.dump(registry, fh, indent=1)
        fh.write("\n")
    card = [f"# Model card: {args.name}", "",
            f"VolSR variant {args.variant}, {cfg.scale}x per axis, {'recurrent, ' if cfg.recurrent else ''}"
            f"{LAYERED.format(cfg.taau_slabs) if cfg.taau_slabs else TAAU_BASED if cfg.taau_base else ''}"
            f"{'seeing what TAAU threw away (the reprojected history and its share of the blend), ' if cfg.taau_aux else ''}"
            f"{'its TAAU told how finely frames sample the volume, ' if cfg.taau_fine_sampling else ''}"
            f"{cfg.previous_frames} previous frames, inputs {', '.join(cfg.features)}; "
            f"{entry['parameters']:,} parameters. Files: `{pt.name}` ({pt.stat().st_size / 2**20:.2f} MiB, weights "
            f"only, `torch.load(weights_only=True)`), `{onnx_path.name}` ({onnx_path.stat().st_size / 2**20:.2f} MiB, "
            f"opset {OPSET}, dynamic height and width). SHA-256 in `models.json`, checked at load.", "",
            "**Intended use: interactive visualisation (upscaling direct volume renderings while the camera moves). "
            f"Not for diagnosis:** {RISK_XS if not cfg.widths else RISK}, and it was trained on a handful of volumes.",
            "",
            "## Training", "", f"Config `{args.config.resolve().relative_to(REPO).as_posix()}`:", "", "```yaml",
            args.config.read_text().strip(), "```", "", args.card_notes.strip(), "", "## Metrics", ""]
    for path in args.eval:
        card += metrics_table(path)
    with atomic_write(MODELS / f"{args.name}.md", "w") as fh:
        fh.write("\n".join(card) + "\n")
    print(json.dumps(entry, indent=1))


if __name__ == "__main__":
    main()
