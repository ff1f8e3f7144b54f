"""Where a network's ``history`` input comes from: decided here, once, for the upscaler, training and evaluation.

A network (:class:`~volsr_core.sr.network_config.NetworkConfig`) takes one of three histories:

- ``"none"``: no history input (the seed paper's network: only its N previous LR frames);
- ``"recurrent"``: its own output for the previous frame (the network warps it to this frame);
  none on the first frame after a cut;
- ``"taau"``: TAAU's estimate of *this* frame (:func:`taau_upsampler`, run over every frame from
  the cut on), which the network refines; for a network with ``taau_aux`` followed by TAAU's side
  outputs (the reprojected history and its share of the blend: 7 channels). With ``taau_fine_sampling``
  the TAAU is told each frame's pixels per voxel (its fine-sampling settings, docs/temporal.md), as the
  TAAU method is; networks trained before datasets recorded it run theirs without. With ``taau_slabs``
  K it is the layered TAAU's estimate (:class:`~volsr_core.temporal.layered.LayeredUpsampler`, one history
  per depth slab), fed each frame's K depth slabs and always told the pixels per voxel (as the upscaler
  runs it: :class:`~volsr_core.runtime.upscaler.StatefulUpscaler`).

:func:`pick_history` is the rule; :class:`HistoryFeed` applies it to a stream of frames (numpy,
as the runtime and ``volsr eval`` run networks); training applies it to batches
(:func:`~volsr_core.sr.network.run_unrolled`) with the TAAU frames the loader computed with the same
:func:`taau_upsampler`. Torch-free, so that onnxruntime-only installs use it too.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from volsr_core.temporal.layered import LayeredUpsampler
from volsr_core.temporal.resample import upscale_bilinear
from volsr_core.temporal.taau import TemporalUpsampler

HISTORY_MODES = ("none", "recurrent", "taau")


def history_mode(config: Any) -> str:
    """The history a network with ``config`` (a NetworkConfig) takes: one of :data:`HISTORY_MODES`."""
    if config.recurrent:
        return "recurrent"
    return "taau" if config.taau_base else "none"


def pick_history(mode: str, previous_output: Any, taau_estimate: Any) -> Any:
    """The history to pass with this frame: None, the previous output (recurrent) or TAAU's estimate."""
    if mode not in HISTORY_MODES:
        raise ValueError(f"history mode must be one of {HISTORY_MODES}, got {mode!r}")
    return {"none": None, "recurrent": previous_output, "taau": taau_estimate}[mode]


def taau_upsampler(scale: int, side_outputs: bool = True) -> TemporalUpsampler:
    """The TAAU a TAAU-based network refines, its settings chosen here for training data, evaluation and
    the runtime alike (a network sees at run time the TAAU it was trained on). :class:`HistoryFeed` tells
    it each frame's ``pixels_per_voxel`` only for a network with ``taau_fine_sampling``, and asks for its
    side outputs (``last_aux``) only for one with ``taau_aux``."""
    return TemporalUpsampler(scale, side_outputs=side_outputs)


def stand_in_history(lr: np.ndarray, scale: int) -> np.ndarray:
    """What stands in for a missing history (a recurrent network's first frame): the current colour,
    bilinearly upscaled, (B, 3, H, W) float32 from ``lr`` (B, N+1, C, h, w) as the network takes it."""
    colour = np.moveaxis(lr[:, 0, :3], 1, -1)  # (B, h, w, 3)
    return np.stack([np.moveaxis(upscale_bilinear(c, scale), -1, 0) for c in colour]).astype(np.float32)


class HistoryFeed:
    """:func:`pick_history` over a stream of frames, one call per frame, numpy (H, W, 3) images.

    ``feed(colour, motion, jitter, depth, rotation, pixels_per_voxel)`` returns this frame's history (or
    None) and must see every frame from the cut on (TAAU accumulates over all of them; ``depth``,
    ``rotation`` and ``pixels_per_voxel`` as :class:`~volsr_core.temporal.taau.TemporalUpsampler` takes
    them, the last passed on only for a network with ``taau_fine_sampling``); a network with ``taau_slabs``
    also takes the frame's ``slabs`` (K, h, w, SLAB_CHANNELS) and the ``background`` they composite over,
    and its estimate is the layered TAAU's of them (a frame in another K than the last starts its history afresh:
    ``Pipeline``'s slabs by look); ``slabs`` (the constructor's) overrides the config's
    ``taau_slabs``, as the upscaler's ``slabs`` does (0: the TAAU on the frame's colour). ``feed.keep(output)``
    hands it the network's output for that frame (a recurrent network's next history). :meth:`reset` is a cut.
    ``device`` "cuda" runs the TAAU (or the layered TAAU) on the GPU (:mod:`volsr_core.temporal.cuda`): frames and
    estimates are then device arrays; only for a TAAU history without side outputs (variant XS).
    """

    def __init__(self, config: Any, slabs: int | None = None, device: str = "cpu"):
        self.mode = history_mode(config)
        self.taau_aux = bool(getattr(config, "taau_aux", False))
        self.slabs = int(getattr(config, "taau_slabs", 0) if slabs is None else slabs)
        self.taau: TemporalUpsampler | None = None
        if device == "cuda" and (self.mode != "taau" or self.taau_aux):
            raise ValueError("the history on the device is a TAAU estimate without side outputs (variant XS)")
        if self.mode == "taau" and device == "cuda":
            from volsr_core.temporal.cuda import CudaLayeredUpsampler, CudaTemporalUpsampler

            self.taau = CudaLayeredUpsampler(config.scale) if self.slabs else CudaTemporalUpsampler(config.scale)
        elif self.mode == "taau":
            self.taau = LayeredUpsampler(config.scale) if self.slabs else taau_upsampler(config.scale, self.taau_aux)
        self.fine_sampling = bool(getattr(config, "taau_fine_sampling", False))
        self.previous: np.ndarray | None = None

    def reset(self) -> None:
        self.previous = None
        if self.taau is not None:
            self.taau.reset()

    def __call__(self, colour: np.ndarray, motion: np.ndarray, jitter: tuple[float, float],
                 depth: np.ndarray | None = None, rotation: float | None = None,
                 pixels_per_voxel: float | None = None, *, slabs: np.ndarray | None = None,
                 background: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 out: np.ndarray | None = None) -> np.ndarray | None:
        parts = self.parts(colour, motion, jitter, depth, rotation, pixels_per_voxel, slabs=slabs,
                           background=background, out=out)
        return None if parts is None else parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)

    def parts(self, colour: np.ndarray, motion: np.ndarray, jitter: tuple[float, float],
              depth: np.ndarray | None = None, rotation: float | None = None,
              pixels_per_voxel: float | None = None, *, slabs: np.ndarray | None = None,
              background: tuple[float, float, float] = (0.0, 0.0, 0.0),
              out: np.ndarray | None = None) -> list[np.ndarray] | None:
        """This frame's history as the (H, W, c) images whose channels, one after the other, make it (None for
        none): the estimate, then, with ``taau_aux``, what its blend threw away. The same call as the feed
        itself, for a caller that lays them out its own way without first joining them (a 7-channel copy).
        ``out``: an (H, W, 3) float32 array (a device array on the GPU) the TAAU writes its estimate into, for a
        caller done with the last one (else each estimate is a new array)."""
        estimate = None
        if self.slabs and self.mode == "taau":  # told the pixels per voxel always, as the upscaler runs it
            if slabs is None:  # any count: a frame in another count than the last starts the history afresh
                raise ValueError("the layered TAAU takes each frame's depth slabs, got none")
            estimate = [self.taau(slabs, jitter, background, rotation, pixels_per_voxel, out=out)]
        elif self.taau is not None:
            estimate = [self.taau(colour, motion, jitter, depth, rotation,
                                  pixels_per_voxel if self.fine_sampling else None, background=background, out=out)]
            if self.taau_aux:
                estimate.append(self.taau.last_aux)
        return pick_history(self.mode, None if self.previous is None else [self.previous], estimate)

    def keep(self, output: np.ndarray) -> None:
        """The network's output for the frame just fed, (H, W, 3)."""
        if self.mode == "recurrent":
            self.previous = output
