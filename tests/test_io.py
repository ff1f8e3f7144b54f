"""Volume loaders: DICOM series (sorting, geometry, series choice, resampling), SimpleITK formats, VTI.

Synthetic DICOM series are written with pydicom; SimpleITK's series reader is the geometry reference.
The helpers at the top are shared with test_io_errors.py.
"""
from __future__ import annotations

import random
import shutil
from pathlib import Path

import numpy as np
import pydicom
import pytest
import SimpleITK as sitk
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from volsr_core.io import SUPPORTED_EXTENSIONS, list_dicom_series, read_volume

HEADSQ_SHAPE_XYZ = (64, 64, 93)
HEADSQ_INTERCEPT = -1024.0


# ---------------------------------------------------------------- helpers (also used by test_io_errors.py)
def copy_series(source: Path, target: Path) -> list[Path]:
    """Copy every file of a series folder into ``target``; return the copies sorted by name."""
    target.mkdir(parents=True, exist_ok=True)
    return sorted(Path(shutil.copy(f, target)) for f in sorted(source.iterdir()))


def position_z(file: Path) -> float:
    """ImagePositionPatient z (mm) of a DICOM file; headsq is axial, so z runs along its normal."""
    return float(pydicom.dcmread(file, stop_before_pixels=True).ImagePositionPatient[2])


def files_by_position(folder: Path) -> list[Path]:
    """The files of an axial DICOM series folder, sorted by ImagePositionPatient z."""
    return sorted(folder.iterdir(), key=position_z)


def as_new_series(files: list[Path], target: Path, description: str) -> str:
    """Write copies of ``files`` into ``target`` as a new series (new Series/SOP Instance UIDs)."""
    uid = generate_uid()
    for i, file in enumerate(files):
        ds = pydicom.dcmread(file)
        ds.SeriesInstanceUID = uid
        ds.SeriesDescription = description
        ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID = generate_uid()
        ds.save_as(target / f"other_{i:03d}.dcm")
    return uid


def write_ct_series(
    folder: Path,
    stored: np.ndarray,
    pixel_spacing: tuple[float, float],
    orientation: np.ndarray,
    positions: np.ndarray,
    names: list[str],
) -> str:
    """Write int16 ``stored`` (z, y, x) as one CT slice per file (intercept -1024); return the series UID.

    ``pixel_spacing`` is DICOM's [row spacing, column spacing]; ``orientation`` the six
    ImageOrientationPatient cosines; ``positions`` (z, 3) each slice's ImagePositionPatient.
    InstanceNumber runs against the spatial order and SliceThickness is wrong, on purpose.
    """
    folder.mkdir(parents=True, exist_ok=True)
    series_uid, study_uid, frame_uid = generate_uid(), generate_uid(), generate_uid()
    for k, (plane, position, name) in enumerate(zip(stored, positions, names)):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID, ds.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
        ds.Modality, ds.PatientID = "CT", "SYNTH"
        ds.StudyInstanceUID, ds.SeriesInstanceUID, ds.FrameOfReferenceUID = study_uid, series_uid, frame_uid
        ds.SeriesNumber, ds.InstanceNumber = 1, len(names) - k
        ds.ImagePositionPatient = [f"{v:.6f}" for v in position]
        ds.ImageOrientationPatient = [f"{v:.8f}" for v in orientation]
        ds.PixelSpacing = [f"{v:g}" for v in pixel_spacing]
        ds.SliceThickness = "9.9"
        ds.Rows, ds.Columns = plane.shape
        ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
        ds.RescaleIntercept, ds.RescaleSlope, ds.RescaleType = "-1024", "1", "HU"
        ds.PixelData = np.ascontiguousarray(plane, dtype="<i2").tobytes()
        ds.save_as(folder / name, enforce_file_format=True)
    return series_uid


def rotation(ax: float, ay: float, az: float) -> np.ndarray:
    """Rotation matrix Rz @ Ry @ Rx for angles in degrees."""
    x, y, z = np.radians([ax, ay, az])
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    return rz @ ry @ rx


def world(record, ijk) -> np.ndarray:
    """LPS mm of voxel centre (i, j, k): origin + direction @ (spacing * ijk)."""
    return np.asarray(record.origin) + record.direction @ (np.asarray(record.spacing) * np.asarray(ijk, float))


# ---------------------------------------------------------------- the shared headsq CT series
def test_headsq_geometry_and_hounsfield_units(headsq_dicom):
    record = read_volume(headsq_dicom)
    assert record.shape_xyz == HEADSQ_SHAPE_XYZ
    assert record.array.dtype == np.float32
    np.testing.assert_allclose(record.spacing, (3.2, 3.2, 1.5), atol=1e-6)
    np.testing.assert_allclose(record.direction, np.eye(3), atol=1e-9)
    assert abs(record.array.min() - (-1024)) <= 3 and abs(record.array.max() - 2902) <= 3
    assert (record.modality, record.units) == ("CT", "HU")
    assert record.source == str(headsq_dicom)
    assert [s.n_files for s in record.series] == [93]


def test_headsq_slices_follow_image_position_not_file_names(headsq_dicom):
    record = read_volume(headsq_dicom)
    by_position = files_by_position(headsq_dicom)
    world_z = [world(record, (0, 0, k))[2] for k in range(record.array.shape[0])]
    np.testing.assert_allclose(world_z, [position_z(f) for f in by_position], atol=1e-4)
    assert np.all(np.diff(world_z) > 0)
    for k in (0, 1, 40, 92):  # each slice holds the pixels of the file at its position, in HU
        expected = pydicom.dcmread(by_position[k]).pixel_array.astype(np.float32) + HEADSQ_INTERCEPT
        np.testing.assert_array_equal(record.array[k], expected)
    # the files are deliberately not named in position order
    assert [f.name for f in by_position] != sorted(f.name for f in by_position)


def test_headsq_under_shuffled_names_gives_the_same_volume(headsq_dicom, tmp_path):
    files = sorted(headsq_dicom.iterdir())
    names = [f"slice{i:03d}" + (".dcm" if i % 2 else "") for i in range(len(files))]  # half without extension
    random.Random(7).shuffle(names)
    for file, name in zip(files, names):
        shutil.copy(file, tmp_path / name)
    original, shuffled = read_volume(headsq_dicom), read_volume(tmp_path)
    np.testing.assert_array_equal(shuffled.array, original.array)
    assert shuffled.origin == original.origin and shuffled.spacing == original.spacing


def test_one_file_of_the_series_loads_the_whole_series(headsq_dicom):
    one = next(f for f in sorted(headsq_dicom.iterdir()) if f.name.endswith("7.dcm"))
    record = read_volume(one)
    assert record.shape_xyz == HEADSQ_SHAPE_XYZ
    np.testing.assert_array_equal(record.array, read_volume(headsq_dicom).array)


def test_series_in_a_subfolder_is_found(headsq_dicom, tmp_path):
    copy_series(headsq_dicom, tmp_path / "PA0" / "ST0" / "SE0")
    (tmp_path / "README.txt").write_text("export notes")
    record = read_volume(tmp_path)
    assert record.shape_xyz == HEADSQ_SHAPE_XYZ
    assert any("ignored 1 non-DICOM" in note for note in record.notes)


def test_two_series_in_one_folder(headsq_dicom, tmp_path):
    copies = copy_series(headsq_dicom, tmp_path)
    main_uid = str(pydicom.dcmread(copies[0], stop_before_pixels=True).SeriesInstanceUID)
    small_uid = as_new_series(files_by_position(tmp_path)[20:30], tmp_path, "small copy")

    record = read_volume(tmp_path)
    assert record.shape_xyz == HEADSQ_SHAPE_XYZ
    assert any(small_uid in note and "10 files" in note for note in record.notes)

    small = read_volume(tmp_path, series_uid=small_uid)
    assert small.shape_xyz == (64, 64, 10)
    np.testing.assert_array_equal(small.array, record.array[20:30])
    assert small.origin == pytest.approx(world(record, (0, 0, 20)))
    assert any(main_uid in note for note in small.notes)

    infos = list_dicom_series(tmp_path)
    assert [(i.series_uid, i.n_files) for i in infos] == [(main_uid, 93), (small_uid, 10)]
    assert (infos[1].description, infos[1].modality, infos[1].rows, infos[1].columns) == ("small copy", "CT", 64, 64)
    # a file of the small series picks its own series
    assert read_volume(tmp_path / "other_000.dcm").shape_xyz == (64, 64, 10)
    assert list_dicom_series(tmp_path / "other_000.dcm") == infos


def test_missing_slice_resampled_on_request(headsq_dicom, tmp_path):
    by_position = files_by_position(headsq_dicom)
    for file in by_position[:40] + by_position[41:]:
        shutil.copy(file, tmp_path)
    record = read_volume(tmp_path, resample=True)
    original = read_volume(headsq_dicom)
    assert record.shape_xyz == HEADSQ_SHAPE_XYZ
    assert record.spacing[2] == pytest.approx(1.5)
    np.testing.assert_array_equal(record.array[:40], original.array[:40])
    np.testing.assert_array_equal(record.array[41:], original.array[41:])
    np.testing.assert_allclose(record.array[40], (original.array[39] + original.array[41]) / 2, atol=1e-3)
    assert any("resampled 92 unevenly spaced slices" in note for note in record.notes)


# ---------------------------------------------------------------- synthetic oblique series vs SimpleITK
@pytest.mark.parametrize("angles", [(0, 0, 0), (20, -35, 50), (180, 10, -70)])
def test_oblique_non_square_series_matches_simpleitk(tmp_path, angles):
    rng = np.random.default_rng(3)
    n_slices, rows, columns = 7, 6, 5
    stored = rng.integers(0, 3000, size=(n_slices, rows, columns), dtype=np.int16)
    axes = rotation(*angles)  # columns: row cosine, column cosine, normal
    pixel_spacing = (0.5, 0.8)  # [row spacing (y), column spacing (x)]
    start, gap = np.array([-40.25, 12.5, 87.0]), 1.25
    positions = start + np.outer(np.arange(n_slices) * gap, axes[:, 2])
    names = [f"f{i}" for i in range(n_slices)]
    random.Random(1).shuffle(names)
    write_ct_series(tmp_path, stored, pixel_spacing, axes[:, :2].T.reshape(-1), positions, names)

    record = read_volume(tmp_path)
    files = sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(tmp_path))
    reference = sitk.ImageSeriesReader()
    reference.SetFileNames(files)
    image = reference.Execute()
    np.testing.assert_allclose(record.spacing, image.GetSpacing(), atol=1e-6)
    np.testing.assert_allclose(record.origin, image.GetOrigin(), atol=1e-4)
    np.testing.assert_allclose(record.direction, np.reshape(image.GetDirection(), (3, 3)), atol=1e-6)
    np.testing.assert_array_equal(record.array, sitk.GetArrayFromImage(image).astype(np.float32))

    # and against DICOM's own definition, independently of SimpleITK
    assert record.spacing == pytest.approx((0.8, 0.5, gap))
    np.testing.assert_array_equal(record.array, stored.astype(np.float32) - 1024)
    for i, j, k in [(0, 0, 0), (4, 0, 0), (0, 5, 3), (4, 5, 6)]:
        dicom = positions[k] + i * pixel_spacing[1] * axes[:, 0] + j * pixel_spacing[0] * axes[:, 1]
        np.testing.assert_allclose(world(record, (i, j, k)), dicom, atol=1e-4)


def test_series_stacked_against_the_normal_is_flipped_into_order(tmp_path):
    """Positions decreasing along the normal in file order: k must still run along +normal."""
    stored = np.arange(4 * 3 * 2, dtype=np.int16).reshape(4, 3, 2)
    axes = rotation(0, 0, 90)
    positions = np.array([0.0, 0.0, 30.0]) - np.outer(np.arange(4) * 2.0, axes[:, 2])
    write_ct_series(tmp_path, stored, (1.0, 1.0), axes[:, :2].T.reshape(-1), positions, ["a", "b", "c", "d"])
    record = read_volume(tmp_path)
    np.testing.assert_array_equal(record.array, stored[::-1].astype(np.float32) - 1024)
    np.testing.assert_allclose(record.origin, positions[-1], atol=1e-6)
    np.testing.assert_allclose(record.direction[:, 2], axes[:, 2], atol=1e-6)
    assert np.linalg.det(record.direction) == pytest.approx(1.0)


# ---------------------------------------------------------------- SimpleITK formats and VTI
SPACING = (0.75, 1.25, 2.5)
ORIGIN = (-10.5, 20.25, 3.0)
DIRECTION = rotation(0, 0, 90) @ rotation(90, 0, 0)  # a proper rotation with exact entries


def _known_image(dtype=np.int16) -> tuple[np.ndarray, sitk.Image]:
    array = np.random.default_rng(5).integers(-1000, 3000, size=(4, 5, 6)).astype(dtype)  # (z, y, x)
    image = sitk.GetImageFromArray(array)
    image.SetSpacing(SPACING)
    image.SetOrigin(ORIGIN)
    image.SetDirection(DIRECTION.reshape(-1).tolist())
    return array, image


@pytest.mark.parametrize("name", ["v.nrrd", "v.nii", "v.nii.gz", "v.mha", "v.mhd", "V.NII.GZ"])
def test_simpleitk_formats_round_trip(tmp_path, name):
    array, image = _known_image()
    sitk.WriteImage(image, str(tmp_path / name.lower()))
    (tmp_path / name.lower()).rename(tmp_path / name)  # extensions are matched case-insensitively
    record = read_volume(tmp_path / name)
    assert record.shape_xyz == (6, 5, 4)
    np.testing.assert_array_equal(record.array, array.astype(np.float32))
    np.testing.assert_allclose(record.spacing, SPACING, atol=1e-6)
    np.testing.assert_allclose(record.origin, ORIGIN, atol=1e-5)
    np.testing.assert_allclose(record.direction, DIRECTION, atol=1e-6)
    assert (record.modality, record.units, record.source) == ("OT", "", str(tmp_path / name))


def test_float_nrrd_and_vector_metaimage(tmp_path):
    array, image = _known_image(np.float32)
    fractions = sitk.Cast(image / 7.0, sitk.sitkFloat32)
    sitk.WriteImage(fractions, str(tmp_path / "f.nrrd"))
    np.testing.assert_array_equal(read_volume(tmp_path / "f.nrrd").array, sitk.GetArrayFromImage(fractions))
    vector = sitk.Compose(image, image * 2)
    sitk.WriteImage(vector, str(tmp_path / "vec.mha"))
    record = read_volume(tmp_path / "vec.mha")
    np.testing.assert_array_equal(record.array, array)
    assert any("component 1 of 2" in note for note in record.notes)


def test_metaimage_modality_tag(tmp_path):
    _, image = _known_image()
    sitk.WriteImage(image, str(tmp_path / "v.mha"))
    data = (tmp_path / "v.mha").read_bytes()
    (tmp_path / "v.mha").write_bytes(data.replace(b"ElementDataFile", b"Modality = MET_MOD_CT\nElementDataFile", 1))
    record = read_volume(tmp_path / "v.mha")
    assert (record.modality, record.units) == ("CT", "")  # CT, but nothing says the values are HU


def write_vti(path: Path, values: np.ndarray, extent_start=(0, 0, 0), direction=DIRECTION) -> None:
    """Write values (z, y, x[, c]) as VTK XML image data with SPACING, ORIGIN and ``direction``."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    nz, ny, nx = values.shape[:3]
    i0, j0, k0 = extent_start
    image = vtkImageData()
    image.SetExtent(i0, i0 + nx - 1, j0, j0 + ny - 1, k0, k0 + nz - 1)
    image.SetSpacing(SPACING)
    image.SetOrigin(ORIGIN)
    image.SetDirectionMatrix(direction.reshape(-1).tolist())
    flat = values.reshape(nx * ny * nz, -1) if values.ndim == 4 else values.reshape(-1)
    scalars = numpy_to_vtk(np.ascontiguousarray(flat), deep=True)
    scalars.SetName("density")
    image.GetPointData().SetScalars(scalars)
    writer = vtkXMLImageDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(image)
    assert writer.Write() == 1


def test_vti_round_trip_with_direction(tmp_path):
    pytest.importorskip("vtkmodules.vtkIOXML")
    array, _ = _known_image(np.float32)
    write_vti(tmp_path / "v.vti", array)
    record = read_volume(tmp_path / "v.vti")
    np.testing.assert_array_equal(record.array, array)
    np.testing.assert_allclose(record.spacing, SPACING)
    np.testing.assert_allclose(record.origin, ORIGIN)
    np.testing.assert_allclose(record.direction, DIRECTION, atol=1e-12)
    assert record.modality == "OT"


def test_vti_extent_offset_and_components(tmp_path):
    """An extent not starting at 0 moves the origin; of several components the first is taken."""
    pytest.importorskip("vtkmodules.vtkIOXML")
    array, _ = _known_image(np.float32)
    write_vti(tmp_path / "v.vti", np.stack([array, -array], axis=-1), extent_start=(2, 0, 3))
    record = read_volume(tmp_path / "v.vti")
    np.testing.assert_array_equal(record.array, array)
    shifted = np.asarray(ORIGIN) + DIRECTION @ (np.asarray(SPACING) * [2, 0, 3])
    np.testing.assert_allclose(record.origin, shifted, atol=1e-12)
    assert any("component 1 of 2" in note and "density" in note for note in record.notes)


# ---------------------------------------------------------------- the shared NIfTI / MetaImage files
def test_shared_ct_avm_nifti(ct_avm_path):
    record = read_volume(ct_avm_path)
    assert record.shape_xyz == (256, 242, 154)
    np.testing.assert_allclose(record.spacing, (0.72, 0.72, 1.0), atol=0.01)
    np.testing.assert_allclose(record.direction, np.diag([-1.0, -1.0, 1.0]), atol=1e-6)  # NIfTI RAS -> LPS
    assert (record.modality, record.units) == ("OT", "")
    assert 0 <= record.array.min() and 500 < record.array.max() < 600


def test_shared_lidc_metaimage(shared_data):
    record = read_volume(shared_data / "volumes" / "LIDC2.mha")
    assert record.shape_xyz == (256, 256, 133)
    np.testing.assert_allclose(record.spacing, (1.406, 1.406, 2.5), atol=0.01)


def test_supported_extensions():
    assert set(SUPPORTED_EXTENSIONS) == {".dcm", ".nrrd", ".nhdr", ".nii", ".nii.gz", ".mha", ".mhd", ".vti"}
