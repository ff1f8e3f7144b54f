"""Training configuration (YAML, BasicSR-style sections): read, validate, fill defaults."""
from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

import yaml

from volsr_core.errors import InputError, read_text_file

DEFAULTS: dict[str, Any] = {
    "seed": 0,
    "out": "runs/default",
    "data": {"root": None, "scale": 4, "previous_frames": 2, "crop": 96,
             "features": ["color", "depth", "max_rgba"], "augment": True, "num_workers": 0,
             "val_crop": None},
    "model": {"variant": "S", "fold": None, "widths": None, "recurrent": False, "taau_base": False, "init": None},
    "optim": {"lr": 1e-3, "weight_decay": 1e-4, "warmup_steps": 100, "min_lr_ratio": 0.05},
    "train": {"steps": 1000, "batch_size": 8, "unroll": 1, "checkpoint_every": 200, "validate_every": None,
              "amp": True, "max_val_samples": 64},
    "loss": {"charbonnier_eps": 1e-3, "ssim_weight": 0.0, "temporal_weight": 0.0},
}


def _merge(base: dict[str, Any], update: dict[str, Any], path: str, source: Path) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in update.items():
        where = f"{path}{key}"
        if key not in base:
            raise InputError(source, f"unknown key '{where}' (known: {', '.join(sorted(base))})")
        if isinstance(base[key], dict):
            if not isinstance(value, dict):
                raise InputError(source, f"'{where}' must be a mapping")
            out[key] = _merge(base[key], value, where + ".", source)
        else:
            out[key] = value
    return out


def load_training_config(path: str | os.PathLike) -> dict[str, Any]:
    """The config at ``path`` over :data:`DEFAULTS`; ``data.root``, ``out`` and ``model.init`` (weights to
    fine-tune from) resolved against the file's folder."""
    source = Path(path)
    text = read_text_file(source)
    try:
        raw = yaml.safe_load(text) or {}
    except yaml.YAMLError as err:
        raise InputError(source, f"not valid YAML: {' '.join(str(err).split())}") from None
    if not isinstance(raw, dict):
        raise InputError(source, "a training config is a YAML mapping")
    config = _merge(DEFAULTS, raw, "", source)
    if not config["data"]["root"]:
        raise InputError(source, "'data.root' (the dataset folder made by `volsr dataset`) is required")
    for section, key in (("data", "root"), (None, "out"), ("model", "init")):
        holder = config[section] if section else config
        if holder[key] is not None:
            holder[key] = str((source.parent / os.path.expandvars(str(holder[key]))).resolve())
    train = config["train"]
    for key in ("steps", "batch_size", "unroll", "checkpoint_every"):
        if not isinstance(train[key], int) or train[key] < 1:
            raise InputError(source, f"'train.{key}' must be a positive integer, got {train[key]!r}")
    return config
