"""Re-export the shipped models' ONNX files from their weights (after an exact rewrite of the graph).

    python training/reexport_onnx.py [NAME ...]   # by default every model in resources/models/models.json
    python training/reexport_onnx.py volsr-S-2x volsr-M-4x volsr-S-4x volsr-S-8x   # the fold rewrite (2026-11-25)

For each model: load ``NAME.pt`` (unchanged), export it with :func:`~volsr_core.runtime.export.export_onnx` to a
temporary file, run the old and the new ONNX side by side in onnxruntime on random inputs of the model's own
shapes (an LR frame of 40 x 24, its history at the model's scale) and refuse (exit 1, nothing replaced) when
their outputs differ by more than ``TOLERANCE``; otherwise replace ``NAME.onnx``, its SHA-256 in
``models.json`` and its size on the first line of the model card. A file that comes out byte for byte the same
is left alone.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "resources" / "models"
TOLERANCE = 1e-5  # largest |old - new| allowed on outputs in [0, 1]: float32 sums in another order


def run_onnx(path: Path, feeds: dict[str, np.ndarray]) -> np.ndarray:
    import onnxruntime as ort

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    names = {i.name for i in session.get_inputs()}
    return session.run(None, {k: v for k, v in feeds.items() if k in names})[0]


def main() -> None:
    from volsr_core.atomic import atomic_write
    from volsr_core.hashing import file_sha256
    from volsr_core.runtime.export import example_inputs, export_onnx, input_names
    from volsr_core.sr.checkpoint import load_model

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("names", nargs="*", help="model names (default: all in models.json)")
    args = parser.parse_args()
    registry_path = MODELS / "models.json"
    registry = json.loads(registry_path.read_text())
    entries = [m for m in registry["models"] if not args.names or m["name"] in args.names]
    for entry in entries:
        onnx_path, card = MODELS / entry["files"]["onnx"], MODELS / entry["files"]["card"]
        model = load_model(MODELS / entry["files"]["pt"], expected_sha256=entry["sha256"]["pt"])
        torch_inputs = example_inputs(model.config, 24, 40)
        feeds = {name: np.ascontiguousarray(t.numpy(), dtype=np.float32)
                 for name, t in zip(input_names(model.config), torch_inputs)}
        with tempfile.TemporaryDirectory(dir=MODELS) as folder:
            fresh = export_onnx(model, Path(folder) / onnx_path.name)
            if fresh.read_bytes() == onnx_path.read_bytes():
                print(f"{entry['name']}: unchanged")
                continue
            difference = float(np.abs(run_onnx(fresh, feeds) - run_onnx(onnx_path, feeds)).max())
            if not difference <= TOLERANCE:
                sys.exit(f"{onnx_path}: the new export differs from the shipped one by {difference:.2e} "
                         f"(> {TOLERANCE:g}); nothing replaced")
            os.replace(fresh, onnx_path)
        entry["sha256"]["onnx"] = file_sha256(onnx_path)
        size = f"`{onnx_path.name}` ({onnx_path.stat().st_size / 2**20:.2f} MiB"
        text = re.sub(re.escape(f"`{onnx_path.name}` (") + r"[0-9.]+ MiB", size, card.read_text(), count=1)
        with atomic_write(card, "w") as fh:
            fh.write(text)
        with atomic_write(registry_path, "w") as fh:
            json.dump(registry, fh, indent=1)
            fh.write("\n")
        print(f"{entry['name']}: re-exported, outputs within {difference:.1e} of the shipped file")


if __name__ == "__main__":
    main()
