"""VolSR inside host applications, as a render post-process: VTK (and PyVista), ParaView, 3D Slicer.

Each host adapter reads the host's volume, transfer function, camera, background and view size,
hands them to :meth:`~volsr_core.runtime.pipeline.Pipeline.update`, renders with the Pipeline and shows
the image back in the host. VTK comes through :mod:`volsr_core.scene.vtk_bridge` only.
"""
