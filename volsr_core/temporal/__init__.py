"""Temporal pieces: jitter, backward warping, supersampled ground truth."""
from volsr_core.temporal.jitter import halton, halton_jitter, jitter_sequence
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.warp import backward_warp

__all__ = ["halton", "halton_jitter", "jitter_sequence", "render_supersampled", "backward_warp"]
