"""VolSR: learned super-resolution for direct volume rendering of medical volumes.

Conventions are written once in docs/conventions.md: world mm in LPS, volume arrays (z, y, x),
images (H, W, C) with pixel (0, 0) at the top left, motion vectors in pixels pointing from the
current pixel to where the same point was in the previous frame, float32 unless stated.
"""
import os

__version__ = "0.1.0"

# numba's OpenMP workers (GNU libgomp, which reads this when it loads) spin GOMP_SPINCOUNT times on a `pause` before
# they sleep: 300,000 by default, about 7.7 ms on the project's Xeon, a core taken after every kernel from what runs
# next (onnxruntime's U-Nets: 1.0-1.4 ms a frame at 512²) and from the host's own threads. 100,000 cost numba's
# kernels nothing measurable (docs/performance.md, "Threads"); a process's own setting wins.
SPIN_COUNT = "100000"
os.environ.setdefault("GOMP_SPINCOUNT", SPIN_COUNT)
