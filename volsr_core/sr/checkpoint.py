"""Checkpoints and model files: written atomically, read with ``torch.load(weights_only=True)``.

A model file holds ``{"format": "volsr-model", "version": 1, "network": NetworkConfig dict,
"state_dict": ..., **extra}``; a training checkpoint holds the whole training state (see
:meth:`volsr_core.sr.training.Trainer.state`). Both load without unpickling arbitrary objects.
"""
from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import torch

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError
from volsr_core.hashing import file_sha256

MODEL_FORMAT = "volsr-model"


def _plain(value: Any) -> Any:
    """Numpy arrays and RNG tuples -> tensors/lists that ``weights_only`` loading accepts."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value.copy())
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def save_checkpoint(path: str | os.PathLike, model: torch.nn.Module | None = None,
                    state: dict[str, Any] | None = None, extra: dict[str, Any] | None = None) -> None:
    """Write a model file (``model``: weights and network config) or a training ``state``, atomically."""
    if (model is None) == (state is None):
        raise ValueError("pass exactly one of model or state")
    if model is not None:
        payload = {"format": MODEL_FORMAT, "version": 1, "network": model.config.to_dict(),
                   "state_dict": model.state_dict(), **(extra or {})}
    else:
        payload = _plain(state)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(path) as fh:
        torch.save(payload, fh)


def _sentences(text: str, limit: int = 160) -> str:
    """The first whole sentences of ``text`` that fit in ``limit`` characters (at least the first one, cut)."""
    kept = ""
    for sentence in " ".join(text.split()).replace(". ", ".\n").splitlines():
        if kept and len(kept) + 1 + len(sentence) > limit:
            break
        kept = f"{kept} {sentence}".strip()
    return kept if len(kept) <= limit else kept[: limit - 3] + "..."


def _load_failure(err: Exception) -> str:
    """Why ``torch.load(weights_only=True)`` refused a file, on one line, without torch's advice to load it
    unsafely: a file that would run code on loading is refused as such; a damaged one is unreadable."""
    if isinstance(err, pickle.UnpicklingError):
        lines = [line.strip() for line in str(err).splitlines() if line.strip()]
        detail = next((line for line in lines if "GLOBAL" in line), None)
        if detail is not None:
            return (f"refused: it holds pickled Python objects that loading would run ({detail.rstrip('.')}); "
                    "VolSR loads only plain tensors and numbers")
        detail = next((line for line in lines[1:] if not line.startswith(("Please file", "Check the documentation"))),
                      lines[-1] if lines else type(err).__name__)
        return f"not a readable PyTorch checkpoint ({_sentences(detail)})"
    return f"not a readable PyTorch checkpoint ({type(err).__name__}: {_sentences(str(err))})"


def load_checkpoint(path: str | os.PathLike, trusted: bool = False) -> dict[str, Any]:
    """Read a model file or training checkpoint; a corrupt or foreign file is a one-line InputError.

    ``trusted`` skips the model-format check (training checkpoints). RNG states come back as
    numpy/python objects ready for ``np.random.set_state`` / ``random.setstate``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such model file")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises many types for foreign or damaged files
        raise InputError(path, _load_failure(err)) from None
    if not isinstance(payload, dict):
        raise InputError(path, "not a VolSR model or checkpoint (no mapping inside)")
    if not trusted and payload.get("format") != MODEL_FORMAT:
        raise InputError(path, f"not a VolSR model file (format {payload.get('format')!r})")
    rng = payload.get("rng")
    if rng:
        numpy_state = rng["numpy"]
        rng["numpy"] = (numpy_state[0], numpy_state[1].numpy(), *numpy_state[2:])
        python_state = rng["python"]
        rng["python"] = (python_state[0], tuple(python_state[1]), python_state[2])
    return payload


def load_model(path: str | os.PathLike, expected_sha256: str | None = None) -> "torch.nn.Module":
    """A SuperResolutionNet from a model file (or a training checkpoint), weights only.

    With ``expected_sha256`` the file's hash must match, else a one-line InputError.
    """
    from volsr_core.sr.network import NetworkConfig, SuperResolutionNet

    if expected_sha256 is not None and Path(path).is_file():
        actual = file_sha256(path)
        if actual != expected_sha256.lower():
            raise InputError(path, f"SHA-256 {actual[:16]}... does not match the expected {expected_sha256[:16]}...")
    payload = load_checkpoint(path, trusted=True)
    if payload.get("format") != MODEL_FORMAT and "model" not in payload:
        raise InputError(path, f"not a VolSR model file or training checkpoint (format {payload.get('format')!r})")
    try:
        model = SuperResolutionNet(NetworkConfig.from_dict(payload["network"], source=path, key="network"))
        model.load_state_dict(payload["state_dict"] if "state_dict" in payload else payload["model"])
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise InputError(path, f"model file does not fit the network: {' '.join(str(err).split())[:160]}") from None
    return model.eval()
