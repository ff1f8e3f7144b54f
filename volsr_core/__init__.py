"""VolSR: learned super-resolution for direct volume rendering of medical volumes.

Conventions are written once in docs/conventions.md: world mm in LPS, volume arrays (z, y, x),
images (H, W, C) with pixel (0, 0) at the top left, motion vectors in pixels pointing from the
current pixel to where the same point was in the previous frame, float32 unless stated.
"""
__version__ = "0.1.0"
