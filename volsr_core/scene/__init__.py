"""What is drawn and from where: Volume, TransferFunction (+ presets), Camera, camera paths.

``volsr_core.scene.vtk_bridge`` (VTK conversions) is imported on its own: the core needs no VTK."""
from volsr_core.scene.volume import Volume
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.camera import Camera
from volsr_core.scene.presets import (
    get_preset, list_presets, load_presets, load_transfer_function, save_presets,
)
from volsr_core.scene.slicer_presets import read_slicer_presets, read_vp_file

__all__ = [
    "Volume", "TransferFunction", "Camera",
    "get_preset", "list_presets", "load_presets", "load_transfer_function", "save_presets",
    "read_slicer_presets", "read_vp_file",
]
