"""NetworkConfig and the sized variants: everything that fixes a network's shape, without PyTorch.

Kept apart from :mod:`volsr_core.sr.network` so that onnxruntime-only installs (a ParaView or
Slicer Python without torch) can read a model's configuration.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from volsr_core.config_reader import Source, read_dataclass

FEATURE_CHANNELS = {"color": 3, "alpha": 1, "depth": 1, "max_rgba": 4, "motion_depth": 1}
SCALES = (2, 4, 8, 16)
VARIANTS = ("XS", "S", "M", "L")  # the sized variants, smallest (fastest) first
# A base filter pair's orientation test (BaseFilter; the CPU kernel in runtime/base_filter.py): the luma of the
# base (these weights, Rec. 601), its central differences gx, gy, and gx * gy smoothed by this binomial along x,
# then y, edge pixels repeated at each step; a pixel takes the second filter where the result is negative.
XS_ORIENTATIONS = {2: 2}  # scale -> XS's filters per colour channel (docs/network.md, "Variant XS"); else 1
ORIENTATION_LUMA = (0.299, 0.587, 0.114)
ORIENTATION_SMOOTHING = (0.0625, 0.25, 0.375, 0.25, 0.0625)


@dataclass(frozen=True)
class NetworkConfig:
    """Everything that fixes a network's shape; saved with its weights."""

    scale: int = 4
    previous_frames: int = 2
    features: tuple[str, ...] = ("color", "depth", "max_rgba")
    fold: int = 4               # pixel-unshuffle factor for reweighting + U-Net (1 = full resolution)
    widths: tuple[int, ...] = (32, 48, 64)  # U-Net channels per level, finest first; () = no U-Net, no residual
    reweight_width: int = 32
    feature_width: int = 32     # the residual block's hidden channels (paper: 32)
    recurrent: bool = False     # history = the previous output, warped to this frame (not in the paper)
    taau_base: bool = False     # history = TAAU's estimate of this frame, and the base the output adds to
    taau_aux: bool = False      # taau_base, and the history also holds what TAAU's blend threw away (TemporalUpsampler.last_aux)
    base_kernel: int = 0        # odd: the base passes through a learned base_kernel² filter per colour channel; 0 = none
    base_orientations: int = 1  # 2: two base filters, each pixel taking the one for its local orientation (BaseFilter)
    taau_fine_sampling: bool = False  # taau_base, its TAAU told each frame's pixels per voxel (smooths fine frames)
    taau_slabs: int = 0         # taau_base on the layered TAAU's estimate of frames rendered in this many depth slabs
                                # (no taau_aux: the layered TAAU has no side outputs)

    def __post_init__(self) -> None:
        if self.scale not in SCALES:
            raise ValueError(f"scale must be one of {SCALES}, got {self.scale}")
        if not 0 <= self.previous_frames <= 3:
            raise ValueError("previous_frames must be 0..3")
        bad = [f for f in self.features if f not in FEATURE_CHANNELS]
        if bad or "color" not in self.features:
            raise ValueError(f"features must include 'color' and come from {tuple(FEATURE_CHANNELS)}, got {self.features}")
        if self.fold < 1 or self.scale % self.fold:
            raise ValueError(f"fold must divide the scale ({self.scale}), got {self.fold}")
        if self.recurrent and self.taau_base:
            raise ValueError("a network's history is either its previous output (recurrent) or TAAU's (taau_base)")
        if self.taau_aux and not self.taau_base:
            raise ValueError("taau_aux adds TAAU's side outputs to a TAAU-based network's history (taau_base)")
        if self.taau_fine_sampling and not self.taau_base:
            raise ValueError("taau_fine_sampling tells a TAAU-based network's TAAU (taau_base) how fine frames are")
        if self.taau_slabs < 0 or (self.taau_slabs and (not self.taau_base or self.taau_aux)):
            raise ValueError(f"taau_slabs puts a TAAU-based network (taau_base, no taau_aux: the layered TAAU has no "
                             f"side outputs) on the layered TAAU: 0 or more, got {self.taau_slabs}")
        if self.base_kernel < 0 or (self.base_kernel and self.base_kernel % 2 == 0):
            raise ValueError(f"base_kernel must be 0 or odd, got {self.base_kernel}")
        if self.base_orientations not in (1, 2) or (self.base_orientations == 2 and not self.base_kernel):
            raise ValueError(f"base_orientations must be 1, or 2 with a base filter (base_kernel), got "
                             f"{self.base_orientations}")
        if not self.widths and not self.base_kernel:
            raise ValueError("a network without a U-Net (widths ()) needs a learned base filter (base_kernel)")
        if not self.widths and (self.recurrent or self.previous_frames):
            raise ValueError("a network without a U-Net (widths ()) filters its base only: no previous frames, "
                             "not recurrent")
        sizes = {"widths": min(self.widths, default=1), "feature_width": self.feature_width,
                 "reweight_width": self.reweight_width}
        for name, size in sizes.items():
            if size < 1:
                raise ValueError(f"{name}: channels must be at least 1, got {getattr(self, name)}")
        object.__setattr__(self, "features", tuple(self.features))
        object.__setattr__(self, "widths", tuple(self.widths))

    @property
    def in_channels(self) -> int:
        return sum(FEATURE_CHANNELS[f] for f in self.features)

    @property
    def takes_history(self) -> bool:
        """Whether the network takes a ``history`` image (recurrent or TAAU-based)."""
        return self.recurrent or self.taau_base

    @property
    def history_channels(self) -> int:
        """Channels of the ``history`` input: RGB, plus TAAU's reprojected history RGB and its blend share
        with ``taau_aux``."""
        return 7 if self.taau_aux else 3

    @property
    def weighted_inputs(self) -> int:
        """Inputs the reweighting network weighs: the previous frames, plus the history if any."""
        return self.previous_frames + int(self.takes_history)

    @property
    def rgbd_channels(self) -> list[int]:
        """Indices of colour (and depth, when present) in a frame's input channels."""
        idx, offset = [], 0
        for f in self.features:
            if f in ("color", "depth"):
                idx += list(range(offset, offset + FEATURE_CHANNELS[f]))
            offset += FEATURE_CHANNELS[f]
        return idx

    @classmethod
    def from_dict(cls, mapping: Any, source: Source = None, key: str = "") -> NetworkConfig:
        """The config saved as ``mapping`` (:meth:`to_dict`, as JSON or in a weights file) at ``key``
        in ``source``; an unknown key, a wrong type or an impossible shape is a one-line InputError."""
        return read_dataclass(cls, mapping, source, key)

    def to_dict(self) -> dict:
        return asdict(self)


def variant_config(variant: str, scale: int = 4, previous_frames: int = 2,
                   features: tuple[str, ...] = ("color", "depth", "max_rgba"),
                   recurrent: bool = False, taau_base: bool = False, taau_aux: bool = False,
                   taau_fine_sampling: bool = False, taau_slabs: int = 0) -> NetworkConfig:
    """The sized variants: S folds by the scale (all convolutions at LR), M by scale/2, L by scale/4.

    XS is no U-Net at all: a learned (2 * scale + 1)² filter per colour channel on the base (TAAU's
    estimate with ``taau_base``, or with ``taau_slabs`` K the layered TAAU's on K depth slabs, else the
    bilinear upscale), wide enough to undo a blur of one LR pixel, at 2x a pair of them chosen per pixel
    by orientation; it reads no previous frames and no side outputs (``previous_frames``, ``recurrent``
    and ``taau_aux`` are ignored). ``taau_slabs`` puts any variant on the layered TAAU (a U-Net too, without
    ``taau_aux``: the layered TAAU has no side outputs).
    """
    variant = variant.upper()
    history = {"recurrent": recurrent, "taau_base": taau_base, "taau_aux": taau_aux,
               "taau_fine_sampling": taau_fine_sampling, "taau_slabs": taau_slabs}
    if variant == "XS":
        return NetworkConfig(scale, 0, features, fold=scale, widths=(), base_kernel=2 * scale + 1, taau_base=taau_base,
                             base_orientations=XS_ORIENTATIONS.get(scale, 1), taau_fine_sampling=taau_fine_sampling,
                             taau_slabs=taau_slabs)
    if variant == "S":
        return NetworkConfig(scale, previous_frames, features, fold=scale, widths=(32, 48, 64), **history)
    if variant == "M":
        return NetworkConfig(scale, previous_frames, features, fold=max(scale // 2, 1), widths=(32, 48, 64), **history)
    if variant == "L":
        return NetworkConfig(scale, previous_frames, features, fold=max(scale // 4, 1), widths=(32, 64, 96), **history)
    raise ValueError(f"variant must be one of {', '.join(VARIANTS)}, got {variant!r}")
