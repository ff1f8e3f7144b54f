"""The shipped models in resources/models: found by variant and scale, checked by SHA-256 before use."""
from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import Any

from volsr_core.errors import InputError
from volsr_core.hashing import file_sha256

REGISTRY = "models.json"


def models_dir() -> Path:
    return Path(str(files("volsr_core.resources") / "models"))


def shipped_models() -> list[dict[str, Any]]:
    """The registry's entries: name, variant, scale, files {onnx, pt} and their sha256, model card."""
    path = models_dir() / REGISTRY
    if not path.is_file():
        return []
    return json.loads(path.read_text(encoding="utf-8"))["models"]


def find_model(variant: str = "S", scale: int = 4) -> dict[str, Any]:
    """The registry entry for ``variant`` at ``scale``; a one-line InputError naming what there is."""
    for entry in shipped_models():
        if entry["variant"] == variant.upper() and entry["scale"] == scale:
            return entry
    have = ", ".join(f"{e['variant']} {e['scale']}x" for e in shipped_models()) or "none"
    raise InputError(models_dir(), f"no shipped model for variant {variant} at {scale}x (shipped: {have})")


def model_file(variant: str = "S", scale: int = 4, kind: str = "onnx") -> Path:
    """The path of a shipped model file (``kind`` "onnx" or "pt"), after checking its SHA-256."""
    entry = find_model(variant, scale)
    path = models_dir() / entry["files"][kind]
    if not path.is_file():
        raise InputError(path, "shipped model file is missing (reinstall volsr)")
    actual = file_sha256(path)
    if actual != entry["sha256"][kind]:
        raise InputError(path, f"SHA-256 {actual[:16]}... does not match the registry's {entry['sha256'][kind][:16]}... "
                         "(damaged or replaced)")
    return path
