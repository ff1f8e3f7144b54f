"""Training configuration (YAML, BasicSR-style sections): read, check, fill defaults.

:func:`load_training_config` reads a file into a :class:`TrainingConfig`, one frozen dataclass
per section, with :func:`~volsr_core.config_reader.read_dataclass`: unknown keys, wrong types
and bounds are one-line InputErrors (``"<file>: train.stepz: unknown key (allowed: ...)"``);
left-out keys take the defaults below.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any, Mapping

from volsr_core.config_reader import Source, read_dataclass, read_yaml, setting
from volsr_core.errors import InputError
from volsr_core.sr.network_config import NetworkConfig, variant_config


@dataclass(frozen=True, kw_only=True)
class DataSection:
    """The dataset and what the network is fed from it (crops in HR pixels; None: whole frames)."""

    root: str = setting(expected="the dataset folder made by `volsr dataset`")
    scale: int = 4
    previous_frames: int = 2
    crop: int | None = 96
    features: tuple[str, ...] = ("color", "depth", "max_rgba")
    augment: bool = True
    num_workers: int = 0
    val_crop: int | None = None


@dataclass(frozen=True, kw_only=True)
class ModelSection:
    """The network: a sized variant (XS, S, M, L), optionally with its own ``fold``, U-Net ``widths`` and the hidden
    channels of its feature block and reweighting (``feature_width``, ``reweight_width``; XS: its ``base_kernel``);
    the history flags as :class:`~volsr_core.sr.network_config.NetworkConfig` has them
    (``taau_slabs`` K: on the layered TAAU of K depth slabs, the dataset's ``slabs``); ``init`` names weights
    (model file or checkpoint) to fine-tune from. ``base_kernel`` (odd) and ``base_orientations`` (1, or 2: a pair
    of filters chosen per pixel by orientation) override the variant's base filter."""

    variant: str = "S"
    fold: int | None = None
    widths: tuple[int, ...] | None = None
    feature_width: int | None = None
    reweight_width: int | None = None
    recurrent: bool = False
    taau_base: bool = False
    taau_aux: bool = False
    taau_fine_sampling: bool = False
    taau_slabs: int = 0
    base_kernel: int | None = None
    base_orientations: int | None = None
    init: str | None = None


@dataclass(frozen=True, kw_only=True)
class OptimSection:
    """AdamW with a linear warm-up, then a cosine down to ``min_lr_ratio`` of ``lr``."""

    lr: float = 1e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 100
    min_lr_ratio: float = 0.05


@dataclass(frozen=True, kw_only=True)
class TrainSection:
    """The loop: steps, batch, frames unrolled per sample, checkpoint and validation periods
    (``validate_every`` None: once per epoch); for a closed-form fit (XS) only ``max_val_samples`` and
    ``fit_bias``."""

    steps: int = setting(1000, low=1)
    batch_size: int = setting(8, low=1)
    unroll: int = setting(1, low=1)
    checkpoint_every: int = setting(200, low=1)
    validate_every: int | None = None
    amp: bool = True
    max_val_samples: int = 64
    fit_bias: bool = True  # closed-form fits (XS): False keeps the filter's bias at 0, so black stays black


@dataclass(frozen=True, kw_only=True)
class LossSection:
    """Charbonnier, plus SSIM and temporal terms at these weights."""

    charbonnier_eps: float = 1e-3
    ssim_weight: float = 0.0
    temporal_weight: float = 0.0


@dataclass(frozen=True, kw_only=True)
class TrainingConfig:
    """A checked training config; ``out`` is the run folder (checkpoints, log.csv)."""

    seed: int = 0
    out: str = "runs/default"
    data: DataSection
    model: ModelSection
    optim: OptimSection
    train: TrainSection
    loss: LossSection

    @classmethod
    def from_dict(cls, mapping: Any, source: Source = None) -> TrainingConfig:
        """The config in ``mapping`` (sections as in the file), checked; errors name ``source``."""
        return read_dataclass(cls, mapping, source)

    def to_dict(self) -> dict[str, Any]:
        """Plain sections (what a checkpoint stores); :meth:`from_dict` reads it back."""
        return asdict(self)

    def updated(self, changes: Mapping[str, Any]) -> TrainingConfig:
        """This config with ``changes`` (sections as in the file, e.g. ``{"train": {"steps": 10}}``)
        over it, checked again."""
        return TrainingConfig.from_dict(_merged(self.to_dict(), changes), "config changes")


def _merged(base: dict[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """``changes`` over ``base``, section by section."""
    out = dict(base)
    for key, value in changes.items():
        both = isinstance(out.get(key), dict) and isinstance(value, Mapping)
        out[key] = _merged(out[key], value) if both else value
    return out


def network_config(config: TrainingConfig) -> NetworkConfig:
    """The network ``config`` trains: its variant's at its scale and inputs, with the model section's overrides;
    ValueError where they make no network."""
    data, model = config.data, config.model
    net = variant_config(model.variant, data.scale, data.previous_frames, data.features, model.recurrent,
                         model.taau_base, model.taau_aux, model.taau_fine_sampling, model.taau_slabs)
    names = ("fold", "widths", "feature_width", "reweight_width", "base_kernel", "base_orientations")
    overrides = {k: getattr(model, k) for k in names if getattr(model, k) is not None}
    return NetworkConfig(**{**net.to_dict(), **overrides}) if overrides else net


def load_training_config(path: str | os.PathLike) -> TrainingConfig:
    """The config at ``path`` with defaults filled; ``data.root``, ``out`` and ``model.init``
    (environment variables expanded) resolved against the file's folder. A model section that makes no network
    is a one-line InputError naming the file."""
    source = Path(path)
    config = TrainingConfig.from_dict(read_yaml(source), source)
    try:
        network_config(config)
    except ValueError as err:
        raise InputError(source, f"model: {err}") from None

    def resolved(written: str | None) -> str | None:
        return None if written is None else str((source.parent / os.path.expandvars(written)).resolve())

    return replace(config, out=resolved(config.out), data=replace(config.data, root=resolved(config.data.root)),
                   model=replace(config.model, init=resolved(config.model.init)))
