"""Volume loaders (DICOM, NRRD, NIfTI, MetaImage, VTI) and the embedded synthetic phantom.

Everything here returns a :class:`VolumeRecord` (float32 voxels (z, y, x), LPS geometry in mm)
or raises :class:`volsr_core.errors.InputError` with a one-line message naming the file.
"""
from volsr_core.io.record import SeriesInfo, VolumeRecord
from volsr_core.io.readers import SUPPORTED_EXTENSIONS, read_volume
from volsr_core.io.dicom import list_dicom_series
from volsr_core.io.phantom import make_phantom

__all__ = ["SeriesInfo", "VolumeRecord", "read_volume", "list_dicom_series", "make_phantom", "SUPPORTED_EXTENSIONS"]
