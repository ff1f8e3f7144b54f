"""The shipped models in resources/models: found by variant and scale, checked by SHA-256 before use."""
from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import Any

from volsr_core.errors import InputError
from volsr_core.hashing import file_sha256
from volsr_core.sr.network_config import VARIANTS

REGISTRY = "models.json"
INT8_KIND = "onnx_int8"
"""The registry's name (``files`` and ``sha256``) for a model's 8-bit ONNX file (:mod:`~volsr_core.runtime.quantize`)."""

DEFAULT_SCALE = 2
"""The scale every host and ``volsr upscale`` take unless told: at 2x the learned path (VolSR XS)
lies above the native + bilinear curve at equal time on a CPU; no 4x or 8x point does
(docs/performance.md)."""

PAYING_NETWORK_SHARE = 0.5
"""The most a network may cost, as a share of the LR render it upscales, to be worth running
(``volsr upscale --variant auto``, and the frame-budget mode's model levels).

The same time spent rendering buys pixels instead: along the native + bilinear curve PSNR rises
2.3-3.3 dB per doubling of the rendered pixels at 512² and 2.7-3.9 at 1024² (1/4 -> 1/2 size, the
four volumes of docs/performance.md, 2 degrees per frame). A network costing half the LR render must
add about 1.3-2.3 dB (log2(1.5) doublings) to the bilinear upscale to pay off: what VolSR XS 2x adds
(1.3-2.5 dB at 512²) for a network of 0.08-0.18 LR renders; the U-Net variants would need far more
on a CPU (S 2x's network costs 2.2-4.8 LR renders at 512² and 1024²)."""


def models_dir() -> Path:
    return Path(str(files("volsr_core.resources") / "models"))


def shipped_models() -> list[dict[str, Any]]:
    """The registry's entries: name, variant, scale, files {onnx, pt} and their sha256, model card."""
    path = models_dir() / REGISTRY
    if not path.is_file():
        return []
    return json.loads(path.read_text(encoding="utf-8"))["models"]


def default_variant(scale: int = DEFAULT_SCALE) -> str:
    """The variant taken at ``scale`` unless one is named: the smallest (fastest) shipped there,
    XS at 2x and 4x, S at 8x; "S" when none ships at ``scale`` (the error then names what does)."""
    shipped = {e["variant"] for e in shipped_models() if e["scale"] == scale}
    return next((v for v in VARIANTS if v in shipped), "S")


def find_model(variant: str = "XS", scale: int = DEFAULT_SCALE) -> dict[str, Any]:
    """The registry entry for ``variant`` at ``scale``; a one-line InputError naming what there is."""
    for entry in shipped_models():
        if entry["variant"] == variant.upper() and entry["scale"] == scale:
            return entry
    have = ", ".join(f"{e['variant']} {e['scale']}x" for e in shipped_models()) or "none"
    raise InputError(models_dir(), f"no shipped model for variant {variant} at {scale}x (shipped: {have})")


def model_file(variant: str = "XS", scale: int = DEFAULT_SCALE, kind: str = "onnx") -> Path:
    """The path of a shipped model file (``kind`` "onnx", "pt" or :data:`INT8_KIND`
    where the model has one), after checking its SHA-256."""
    entry = find_model(variant, scale)
    path = models_dir() / entry["files"][kind]
    if not path.is_file():
        raise InputError(path, "shipped model file is missing (reinstall volsr)")
    actual = file_sha256(path)
    if actual != entry["sha256"][kind]:
        raise InputError(path, f"SHA-256 {actual[:16]}... does not match the registry's "
                         f"{entry['sha256'][kind][:16]}... (damaged or replaced)")
    return path


def model_file_to_run(variant: str = "XS", scale: int = DEFAULT_SCALE, device: str = "cpu") -> Path:
    """The ONNX file to run for the shipped model of ``variant`` at ``scale`` on ``device`` (SHA-256 checked): on the
    CPU its 8-bit copy where one ships (:mod:`~volsr_core.runtime.quantize`: every U-Net, whose step after the render
    it shortens by 1.3-20 ms at 512² for 0.002-0.18 dB, S 2x's up to 0.50 at 1024²; docs/performance.md, "8-bit
    U-Nets on the CPU"), else (XS, a
    numba kernel on the float32 file's weights), and on a GPU, the float32 file. A caller that wants float32 on the
    CPU takes :func:`model_file`."""
    kind = INT8_KIND if device == "cpu" and INT8_KIND in find_model(variant, scale)["files"] else "onnx"
    return model_file(variant, scale, kind)
