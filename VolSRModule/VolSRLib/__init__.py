"""Helpers of the VolSR scripted module (Slicer's ``<ModuleName>Lib`` convention: a package beside VolSR.py).

- :mod:`VolSRLib.bootstrap`: VolSR's Python dependencies installed into Slicer at first use, and
  ``volsr_core`` imported from an installed ``volsr`` or from the source checkout.

Slicer puts the folder of VolSR.py on ``sys.path``, so VolSR.py imports this package as ``VolSRLib``.
"""
