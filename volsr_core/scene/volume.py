"""The scalar volume the renderer draws: voxels plus geometry in world millimetres (LPS)."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from volsr_core.io import VolumeRecord, read_volume


@dataclass
class Volume(VolumeRecord):
    """A float32 volume indexed (z, y, x) with geometry in world mm, LPS (like DICOM/ITK).

    ``world = origin + direction @ (spacing * [i, j, k])`` for the voxel ``array[k, j, i]``;
    ``spacing`` is (x, y, z) in mm, ``direction`` has the index axes' world directions as columns.
    ``modality`` is the DICOM modality code ("CT", "MR", "OT") and ``units`` the value units
    ("HU" for CT in Hounsfield units, "" when unknown).
    """

    @classmethod
    def load(cls, path: str | os.PathLike, series_uid: str | None = None, resample: bool = False) -> "Volume":
        """Read a DICOM folder/file, NRRD, NIfTI, MetaImage or VTI file (see :func:`volsr_core.io.read_volume`)."""
        return cls.from_record(read_volume(path, series_uid=series_uid, resample=resample))

    @classmethod
    def from_record(cls, record: VolumeRecord) -> "Volume":
        return cls(**{name: getattr(record, name) for name in VolumeRecord.__dataclass_fields__})

    @property
    def index_to_world(self) -> np.ndarray:
        """4x4 matrix taking homogeneous (i, j, k, 1) voxel indices to world (mm, LPS)."""
        m = np.eye(4)
        m[:3, :3] = self.direction @ np.diag(self.spacing)
        m[:3, 3] = self.origin
        return m

    @property
    def world_to_index(self) -> np.ndarray:
        """4x4 inverse of :attr:`index_to_world`."""
        return np.linalg.inv(self.index_to_world)

    @property
    def corners(self) -> np.ndarray:
        """(8, 3) world positions of the corner voxel centres, the box the renderer samples."""
        nx, ny, nz = self.shape_xyz
        idx = np.array([[i, j, k, 1.0] for k in (0, nz - 1) for j in (0, ny - 1) for i in (0, nx - 1)])
        return (idx @ self.index_to_world.T)[:, :3]

    @property
    def bounds(self) -> tuple[float, float, float, float, float, float]:
        """Axis-aligned world bounds (xmin, xmax, ymin, ymax, zmin, zmax) in mm, like vtkProp.GetBounds()."""
        c = self.corners
        lo, hi = c.min(axis=0), c.max(axis=0)
        return (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])

    @property
    def center(self) -> np.ndarray:
        """World position (mm) of the box centre."""
        return self.corners.mean(axis=0)

    @property
    def value_range(self) -> tuple[float, float]:
        """(min, max) voxel value."""
        return float(self.array.min()), float(self.array.max())

    def percentiles(self, low: float = 0.5, high: float = 99.5) -> tuple[float, float]:
        """Voxel values at the given percentiles (robust range for placing transfer functions)."""
        lo, hi = np.percentile(self.array[::2, ::2, ::2], [low, high])
        return float(lo), float(hi)
