"""Ray casting: the shared ray program (stages), CPU and CUDA kernels, feature buffers."""
from volsr_core.render.features import FeatureFrame
from volsr_core.render.raycaster import RayCaster

__all__ = ["FeatureFrame", "RayCaster"]
