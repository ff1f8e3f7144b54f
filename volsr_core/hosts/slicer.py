"""VolSR in 3D Slicer: the parts that need no Slicer (the module VolSRModule/VolSR.py uses them).

Slicer's world is RAS millimetres, VolSR's is LPS (docs/conventions.md): ``LPS = diag(-1, -1, 1) @ RAS``
(:data:`RAS_TO_LPS`), a half turn about the superior axis. Being a rotation, not a mirror, it changes
no picture: the same voxels seen by the same camera, both carried by it, give the same image. So

- a Slicer volume node's voxels ``arrayFromVolume(node)[k, j, i]`` with its IJK-to-RAS matrix ``M``
  become the :class:`Volume` whose index-to-world is ``RAS_TO_LPS @ M``
  (:func:`volume_from_ijk_to_ras`): origin and the i/j/k direction columns have x and y negated;
- the 3D view's vtkCamera (RAS) becomes our :class:`Camera` with position, focal point and view
  up negated in x and y (:func:`camera_ras_to_lps`); the VTK adapter does this on every render
  when given ``world_matrix=RAS_TO_LPS``.

:class:`SlicerSession` attaches :class:`~volsr_core.hosts.vtk_adapter.VolSRPostProcess` to the
3D view's renderer (overlay on layer 3: Slicer draws on layers 0-2) and reads frame times back;
it takes plain VTK objects, so the same code runs in Slicer and in an offscreen VTK window.
VTK comes through :mod:`volsr_core.scene.vtk_bridge` (Slicer's own VTK; it leaves Slicer's window class alone).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from volsr_core.scene.camera import Camera
from volsr_core.scene.presets import get_preset, list_presets, place_on_volume
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume

from volsr_core.hosts.vtk_adapter import VolSRPostProcess
from volsr_core.runtime.models import default_variant
from volsr_core.scene.camera import transform_camera
from volsr_core.scene.vtk_bridge import matrix_4x4, write_volume_property
from volsr_core.sr.network_config import VARIANTS

RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])
LPS_TO_RAS = RAS_TO_LPS.copy()  # its own inverse
SLICER_OVERLAY_LAYER = 3
SCALES = (2, 4, 8)


# coordinates ------------------------------------------------------------------------------------
def ras_to_lps(points: Any) -> np.ndarray:
    """Points (..., 3) from RAS to LPS mm: x and y change sign."""
    p = np.array(points, dtype=np.float64)
    if p.shape[-1] != 3:
        raise ValueError(f"expected points of 3 coordinates, got shape {p.shape}")
    p[..., :2] *= -1.0
    return p


def lps_to_ras(points: Any) -> np.ndarray:
    """Points (..., 3) from LPS to RAS mm (the same sign change)."""
    return ras_to_lps(points)


def ijk_to_lps(ijk_to_ras: Any) -> np.ndarray:
    """A volume node's 4x4 IJK-to-RAS matrix (numpy or vtkMatrix4x4) as IJK-to-LPS."""
    return RAS_TO_LPS @ matrix_4x4(ijk_to_ras)


def camera_ras_to_lps(camera: Camera) -> Camera:
    """A camera given in RAS coordinates (Slicer's vtkCamera read as is) in LPS."""
    return transform_camera(camera, RAS_TO_LPS)


def camera_lps_to_ras(camera: Camera) -> Camera:
    """A camera in LPS as Slicer's RAS vtkCamera would hold it."""
    return transform_camera(camera, LPS_TO_RAS)


def volume_from_ijk_to_ras(array_kji: np.ndarray, ijk_to_ras: Any, *, modality: str = "OT", units: str = "",
                           source: str = "<Slicer volume node>") -> Volume:
    """Our :class:`Volume` (LPS) from a Slicer volume node's voxels and IJK-to-RAS matrix.

    ``array_kji`` is what ``slicer.util.arrayFromVolume`` gives: indexed (k, j, i) = (z, y, x), one
    scalar per voxel; ``ijk_to_ras`` a 4x4 numpy array or vtkMatrix4x4 (the node's, or the product
    with its parent transform to world). Spacing = the lengths of the matrix's columns, direction =
    the columns normalised, after x and y changed sign; the matrix must not shear.
    """
    array = np.asarray(array_kji)
    if array.ndim != 3:
        raise ValueError(f"VolSR draws scalar volumes (k, j, i); got an array of shape {array.shape}")
    m = ijk_to_lps(ijk_to_ras)
    spacing = np.linalg.norm(m[:3, :3], axis=0)
    if np.any(spacing <= 0):
        raise ValueError(f"the IJK-to-RAS matrix has a zero column (spacing {spacing.tolist()})")
    return Volume(array=array, spacing=tuple(float(s) for s in spacing), origin=tuple(m[:3, 3]),
                  direction=m[:3, :3] / spacing, modality=modality, units=units, source=source)


def ijk_to_ras_of(volume: Volume) -> np.ndarray:
    """The 4x4 IJK-to-RAS matrix a Slicer volume node needs to hold ``volume`` (LPS) in place."""
    return LPS_TO_RAS @ volume.index_to_world


def guess_units(volume: Volume) -> str:
    """The value units of ``volume``: its own, else "HU" when the values reach air in Hounsfield units
    (below -500), else "". Slicer's volume nodes do not record units; presets are placed by them."""
    if volume.units:
        return volume.units
    return "HU" if volume.value_range[0] < -500.0 else ""


def preset_for(name: str, volume: Volume) -> TransferFunction:
    """Our preset ``name``, placed on ``volume`` as ``--range auto`` places it: as designed on a
    volume in its units (HU presets on CT in HU), else on the volume's 0.5-99.5 percentiles."""
    if volume.units != guess_units(volume):
        from dataclasses import replace

        volume = replace(volume, units=guess_units(volume))
    return place_on_volume(get_preset(name), volume, "auto")


def preset_names() -> list[str]:
    """The shipped preset names, for the module's combo box."""
    return list(list_presets())


# the 3D view -------------------------------------------------------------------------------------------
def find_vtk_volume(renderer):
    """The first visible vtkVolume of ``renderer`` (Slicer's ray-cast modes draw one per volume node).

    Slicer's multi-volume mode draws a vtkMultiVolume, which VolSR does not take: ValueError.
    """
    volumes = renderer.GetVolumes()
    volumes.InitTraversal()
    found, multi = None, False
    for _ in range(volumes.GetNumberOfItems()):
        prop = volumes.GetNextVolume()
        if prop.IsA("vtkMultiVolume"):
            multi = True
            continue
        if found is None and prop.GetVisibility() and prop.GetMapper() is not None:
            found = prop
    if found is None:
        raise ValueError("no visible volume in the 3D view" + (
            " (VolSR cannot draw Slicer's multi-volume rendering: choose GPU or CPU ray casting)" if multi else
            " (show the volume with Volume Rendering first)"))
    return found


# the session ----------------------------------------------------------------------------------------
class SlicerSession:
    """VolSR drawing one volume of a Slicer 3D view (or of any VTK renderer whose world is RAS).

    - ``renderer``: the 3D view's first renderer; ``vtk_volume``: the vtkVolume that shows the
      volume node there (its vtkVolumeProperty is read, it is hidden while VolSR draws);
    - ``volume``: our Volume in LPS (:func:`volume_from_ijk_to_ras`); None reads the vtkVolume's
      vtkImageData and matrix (Slicer puts the IJK-to-RAS matrix there) and converts them;
    - ``model``, ``scale`` (2, 4, 8), ``variant`` (XS, S, M, L), ``device``, ``backend``, ``threads``,
      ``sample_distance``: as :class:`VolSRPostProcess` takes them (None scale and variant: the
      Pipeline's defaults, VolSR XS 2x); ``layer``: the overlay's window layer, at least
      :data:`SLICER_OVERLAY_LAYER`.
    """

    def __init__(self, renderer, vtk_volume, volume: Volume | None = None, model: Any = None, *,
                 scale: int | None = None, variant: str | None = None, layer: int = SLICER_OVERLAY_LAYER,
                 device: str = "cpu", backend: str = "auto", threads: int | None = None,
                 sample_distance: float | None = None, enabled: bool = True):
        if scale is not None and int(scale) not in SCALES:
            raise ValueError(f"scale must be one of {SCALES}, got {scale}")
        if variant is not None and str(variant).upper() not in VARIANTS:
            raise ValueError(f"variant must be one of {VARIANTS}, got {variant!r}")
        layer = max(int(layer), SLICER_OVERLAY_LAYER, renderer.GetLayer() + 1)
        self.adapter = VolSRPostProcess(renderer, vtk_volume, volume, model,
                                        scale=None if scale is None else int(scale),
                                        variant=None if variant is None else str(variant).upper(),
                                        layer=layer, device=device, backend=backend, threads=threads,
                                        sample_distance=sample_distance, enabled=enabled, world_matrix=RAS_TO_LPS)
        self.scale = self.adapter.pipeline.scale
        self.variant = str(variant).upper() if variant is not None else (  # the shipped model's, at the scale it runs
            default_variant(self.adapter.pipeline.model_scale) if model is None else "custom")

    @property
    def enabled(self) -> bool:
        return self.adapter.enabled

    @enabled.setter
    def enabled(self, on: bool) -> None:
        self.adapter.enabled = on

    @property
    def renderer(self):
        return self.adapter.renderer

    @property
    def vtk_volume(self):
        return self.adapter.vtk_volume

    def set_volume(self, volume: Volume) -> None:
        """New voxels or geometry (the node's image or transform changed); the history restarts."""
        self.adapter.set_volume(volume)

    def render(self) -> None:
        self.adapter.render()

    def detach(self) -> None:
        """Remove the overlay and the observers: Slicer draws the volume itself again."""
        self.adapter.detach()

    @property
    def timings(self) -> dict[str, float]:
        """ms of the last VolSR frame: render_ms (LR ray cast), network_ms, total_ms ({} before one)."""
        return dict(self.adapter.pipeline.last_timings)

    @property
    def frame_time_ms(self) -> float | None:
        """ms VolSR spent on the last frame (ray cast + network), None before the first."""
        return self.timings.get("total_ms")

    @property
    def last_error(self) -> str:
        return self.adapter.last_error

    def status_text(self) -> str:
        """One line for the module's frame-time label."""
        adapter = self.adapter
        if not adapter.enabled:
            return "off"
        if adapter.last_error:
            return f"Slicer draws the volume ({adapter.last_error})"
        t = self.timings
        if not t:
            return "waiting for the first frame"
        (w, h), (lw, lh) = adapter.pipeline.size, adapter.pipeline.low_resolution_size
        fps = 1000.0 / t["total_ms"] if t["total_ms"] > 0 else float("inf")
        stretch = adapter.pipeline.stretch  # "auto": 2 where a voxel spans two pixels or more, or the view turns fast
        network = (f"{self.variant} {self.scale}x" if stretch == 1
                   else f"{self.variant} {self.scale // stretch}x + bicubic {stretch}x")
        return (f"{t['total_ms']:.1f} ms/frame ({fps:.1f} fps): ray cast {lw}x{lh} {t['render_ms']:.1f} ms + "
                f"{network} network to {w}x{h} {t['network_ms']:.1f} ms")


def session_for(renderer, vtk_volume, array_kji: np.ndarray, ijk_to_ras: Any, model: Any = None, *,
                preset: str | None = None, **options: Any) -> SlicerSession:
    """A :class:`SlicerSession` for a volume node's voxels and IJK-to-RAS matrix; ``preset`` (one of
    :func:`preset_names`) is first written into the vtkVolume's property, placed on the voxels."""
    volume = volume_from_ijk_to_ras(array_kji, ijk_to_ras)
    if preset:
        write_volume_property(vtk_volume.GetProperty(), preset_for(preset, volume))
    return SlicerSession(renderer, vtk_volume, volume, model, **options)


__all__: Sequence[str] = [
    "RAS_TO_LPS", "LPS_TO_RAS", "SLICER_OVERLAY_LAYER", "SCALES", "VARIANTS", "ras_to_lps", "lps_to_ras",
    "ijk_to_lps", "camera_ras_to_lps", "camera_lps_to_ras", "volume_from_ijk_to_ras",
    "ijk_to_ras_of", "guess_units", "preset_for", "preset_names", "find_vtk_volume",
    "SlicerSession", "session_for",
]
