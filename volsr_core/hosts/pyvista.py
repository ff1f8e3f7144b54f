"""VolSR in PyVista: :func:`add_sr_volume` adds a volume like ``Plotter.add_volume`` and draws it
with the SR pipeline (:class:`~volsr_core.hosts.vtk_adapter.VolSRPostProcess` on ``plotter.renderer``).

PyVista's world is VTK's, which is VolSR's: LPS millimetres (docs/pyvista.md). Works with
``pv.Plotter(off_screen=True)`` (EGL). Needs ``pip install 'volsr[pyvista]'``.
"""
from __future__ import annotations

import os
from typing import Any, Sequence

import numpy as np

from volsr_core.hosts.vtk_adapter import VolSRPostProcess
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume
from volsr_core.scene.vtk_bridge import image_data, placement_matrix, to_vtk_volume_property

import pyvista as pv  # noqa: E402  (after the bridge: it chose the offscreen window)


def to_pyvista(volume: Volume) -> tuple["pv.ImageData", np.ndarray]:
    """Our Volume as a ``pv.ImageData`` (spacing only, origin 0, point scalars "scalars") plus the
    4x4 user matrix (direction and origin) that places it in the world, as ``add_volume`` takes it."""
    return pv.wrap(image_data(volume, "scalars", placed=False)), placement_matrix(volume)


def add_sr_volume(plotter: "pv.Plotter", volume: Any, scalars: str | np.ndarray | None = None, *,
                  transfer_function: TransferFunction | str | None = None, clim: Sequence[float] | None = None,
                  cmap: Any = None, opacity: Any = None, shade: bool | None = None, ambient: float | None = None,
                  diffuse: float | None = None, specular: float | None = None,
                  specular_power: float | None = None, opacity_unit_distance: float | None = None,
                  scale: int | None = None, model: Any = None, variant: str | None = None, layer: int | None = None,
                  device: str = "cpu", backend: str = "auto", fp16: bool = False, threads: int | None = None,
                  sample_distance: float | None = None, slabs: int | None = None, stretch: int | str = "auto",
                  enabled: bool = True, show_scalar_bar: bool = False,
                  **add_volume_options: Any) -> VolSRPostProcess:
    """Add ``volume`` to ``plotter`` as ``add_volume`` does and draw it with VolSR; returns the adapter.

    - ``volume``: our :class:`Volume`, a path VolSR reads (DICOM folder, NRRD, NIfTI, MHA, VTI),
      or a ``pv.ImageData`` / vtkImageData in world mm (LPS);
    - the look, either VolSR's: ``transfer_function`` (a TransferFunction or a preset name such
      as "CT-AAA"; ``clim`` then places it on that value range, as ``volsr render --range`` does),
      or PyVista's: ``cmap``, ``opacity`` (a name like "sigmoid" or an array), ``clim`` — these
      build the vtkVolumeProperty exactly as ``add_volume`` does and VolSR reads it back;
    - ``shade``, ``ambient``, ``diffuse``, ``specular``, ``specular_power``,
      ``opacity_unit_distance``: as ``add_volume`` names them; None keeps the transfer function's
      (or PyVista's default);
    - ``scale``, ``model`` (None: the shipped model of ``variant`` at ``scale``), ``layer``,
      ``device``, ``backend``, ``fp16``, ``threads``, ``sample_distance``, ``slabs``, ``stretch``, ``enabled``: as
      :class:`VolSRPostProcess` takes them;
    - ``show_scalar_bar`` defaults to False: a bar in ``plotter.renderer`` would lie under the
      SR overlay; other ``add_volume`` keywords (``mapper``, ``name``, ``reset_camera``, ...)
      pass through and drive the host's own rendering, which is what shows when VolSR is off.

    The vtkVolume is ``adapter.vtk_volume``; ``adapter.enabled = False`` switches VolSR off.
    """
    ours: Volume | None = None
    matrix = None
    if isinstance(volume, (str, os.PathLike)):
        volume = Volume.load(volume)
    if isinstance(volume, Volume):
        ours = volume
        volume, matrix = to_pyvista(volume)
    elif not isinstance(volume, pv.ImageData):
        volume = pv.wrap(volume)
        if not isinstance(volume, pv.ImageData):
            raise TypeError(f"VolSR draws image data (pv.ImageData, vtkImageData, Volume), not {type(volume).__name__}")

    tf = None
    if transfer_function is not None:
        if isinstance(transfer_function, str):
            from volsr_core.scene.presets import get_preset

            tf = get_preset(transfer_function)
        else:
            tf = transfer_function
        if clim is not None:
            tf = tf.placed_on(float(clim[0]), float(clim[1]))
        if cmap is not None or opacity is not None:
            raise ValueError("give either transfer_function or PyVista's cmap/opacity, not both")

    options = dict(add_volume_options)
    for key, value in (("cmap", cmap), ("opacity", opacity), ("shade", shade), ("ambient", ambient),
                       ("diffuse", diffuse), ("specular", specular), ("specular_power", specular_power),
                       ("opacity_unit_distance", opacity_unit_distance)):
        if value is not None:
            options[key] = value
    if clim is not None and tf is None:
        options["clim"] = clim
    if matrix is not None:
        options["user_matrix"] = matrix
    actor = plotter.add_volume(volume, scalars=scalars, show_scalar_bar=show_scalar_bar, **options)

    if tf is not None:
        prop = to_vtk_volume_property(tf)
        for setter, value in (("SetShade", None if shade is None else int(bool(shade))), ("SetAmbient", ambient),
                              ("SetDiffuse", diffuse), ("SetSpecular", specular),
                              ("SetSpecularPower", specular_power),
                              ("SetScalarOpacityUnitDistance", opacity_unit_distance)):
            if value is not None:
                getattr(prop, setter)(value)
        actor.SetProperty(prop)
    if ours is not None and scalars is not None:
        ours = None  # other scalars than the Volume's own: read them from the mapper's input
    return VolSRPostProcess(plotter.renderer, actor, ours, model, scale=scale, variant=variant, layer=layer,
                            device=device, backend=backend, fp16=fp16, threads=threads,
                            sample_distance=sample_distance, slabs=slabs, stretch=stretch, enabled=enabled)
