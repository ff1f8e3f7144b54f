"""Temporal pieces: jitter, backward warping, resampling, supersampled ground truth, TAA and temporal upsampling."""
from volsr_core.temporal.jitter import halton, halton_jitter, jitter_phases, jitter_sequence
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.taa import TemporalAntiAliasing
from volsr_core.temporal.resample import resize_bicubic, resize_bilinear, upscale_bicubic, upscale_bilinear
from volsr_core.temporal.taau import TemporalUpsampler, view_rotation
from volsr_core.temporal.warp import backward_warp

__all__ = ["halton", "halton_jitter", "jitter_sequence", "render_supersampled", "backward_warp",
           "TemporalAntiAliasing", "TemporalUpsampler", "view_rotation", "jitter_phases", "upscale_bilinear",
           "upscale_bicubic", "resize_bilinear", "resize_bicubic"]
