"""Bad input to the volume loaders: every case is an InputError whose message is one line,
names the offending file or folder, and says what is wrong."""
from __future__ import annotations

import contextlib
import gzip
import io
import shutil
import sys
from pathlib import Path

import numpy as np
import pydicom
import pytest
import SimpleITK as sitk
from pydicom.uid import generate_uid

from test_io import as_new_series, copy_series, files_by_position, write_ct_series
from volsr_core.cli import main as volsr_main
from volsr_core.errors import InputError
from volsr_core.io import list_dicom_series, read_volume


def expect_error(path: Path, *phrases: str, name: str | None = None, **kwargs) -> str:
    """read_volume(path) must raise a one-line InputError naming ``name`` (default: path's name)
    and containing every phrase (case-insensitive); ``volsr info`` on it must print that line
    and exit with 2. Returns the message."""
    with pytest.raises(InputError) as caught:
        read_volume(path, **kwargs)
    message = str(caught.value)
    assert "\n" not in message and "Traceback" not in message
    assert (name or path.name) in message
    for phrase in phrases:
        assert phrase.lower() in message.lower(), message
    argv = ["info", str(path)] + (["--series", kwargs["series_uid"]] if kwargs.get("series_uid") else []) \
        + (["--resample"] if kwargs.get("resample") else [])
    stderr, stdout = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(stderr), contextlib.redirect_stdout(stdout):
        code = volsr_main(argv)
    assert code == 2 and stdout.getvalue() == ""
    assert stderr.getvalue() == f"volsr: error: {message}\n"
    return message


def _image(shape_zyx, dtype=np.float32) -> sitk.Image:
    return sitk.GetImageFromArray(np.ones(shape_zyx, dtype=dtype))


# ---------------------------------------------------------------- paths and folders
def test_missing_path(tmp_path):
    expect_error(tmp_path / "nowhere.nii.gz", "no such file or folder")


def test_empty_folder(tmp_path):
    expect_error(tmp_path, "folder is empty")
    with pytest.raises(InputError, match="folder is empty"):
        list_dicom_series(tmp_path)


def test_folder_of_text_files(tmp_path):
    for i in range(3):
        (tmp_path / f"notes{i}.txt").write_text("not a scan\n" * 20)
    expect_error(tmp_path, "no DICOM image files", "3 files", "notes0.txt")


def test_unsupported_extension(tmp_path):
    (tmp_path / "scan.xyz").write_bytes(b"\x00" * 300)
    message = expect_error(tmp_path / "scan.xyz", "unsupported file type '.xyz'")
    for ext in (".nrrd", ".nii.gz", ".mha", ".vti", ".dcm"):
        assert ext in message


def test_file_without_extension_that_is_not_dicom(tmp_path):
    (tmp_path / "scan").write_text("hello")
    expect_error(tmp_path / "scan", "not a DICOM file", 'starts with "hello"')


# ---------------------------------------------------------------- content that does not match the name
@pytest.mark.parametrize(
    "name, phrase",
    [
        ("x.nii.gz", "gzip-compressed NIfTI"),
        ("x.nii", "NIfTI"),
        ("x.nrrd", "NRRD"),
        ("x.nhdr", "NRRD"),
        ("x.mha", "MetaImage"),
        ("x.mhd", "MetaImage"),
        ("x.vti", "VTK XML image data (.vti)"),
        ("x.dcm", "DICOM"),
    ],
)
def test_random_bytes_under_a_volume_name(tmp_path, name, phrase):
    (tmp_path / name).write_bytes(np.random.default_rng(0).bytes(1000))
    expect_error(tmp_path / name, f"content does not look like a {phrase} file", "starts with bytes")


def test_gzip_of_something_else_named_nii_gz(tmp_path):
    (tmp_path / "x.nii.gz").write_bytes(gzip.compress(b"just text, no header" * 40))
    expect_error(
        tmp_path / "x.nii.gz", "does not look like a gzip-compressed NIfTI", 'gzip data that starts with "just'
    )


def test_nifti_saved_under_the_wrong_extension(tmp_path):
    sitk.WriteImage(_image((3, 3, 3)), str(tmp_path / "v.nii.gz"))
    shutil.copy(tmp_path / "v.nii.gz", tmp_path / "v.nrrd")
    shutil.copy(tmp_path / "v.nii.gz", tmp_path / "v.nii")
    expect_error(tmp_path / "v.nrrd", "does not look like a NRRD file", "1f 8b")
    expect_error(tmp_path / "v.nii", "does not look like a NIfTI file", "name it .nii.gz")


def test_empty_file(tmp_path):
    (tmp_path / "x.mha").write_bytes(b"")
    expect_error(tmp_path / "x.mha", "the file is empty")


# ---------------------------------------------------------------- wrong shape or values
@pytest.mark.parametrize("name", ["flat.nrrd", "flat.nii.gz", "flat.mha"])
def test_two_dimensional_image(tmp_path, name):
    sitk.WriteImage(_image((8, 9)), str(tmp_path / name))
    expect_error(tmp_path / name, "expected a 3-D volume, got a 2-D image")


@pytest.mark.parametrize("name", ["thin.nrrd", "thin.mha"])
def test_one_voxel_thick_volume(tmp_path, name):
    sitk.WriteImage(_image((1, 8, 9)), str(tmp_path / name))
    expect_error(tmp_path / name, "at least 2 voxels along every axis")


def test_nan_values(tmp_path):
    array = np.zeros((3, 4, 5), np.float32)
    array[1, 2, 3], array[0, 0, 0] = np.nan, np.inf
    sitk.WriteImage(sitk.GetImageFromArray(array), str(tmp_path / "nan.nrrd"))
    expect_error(tmp_path / "nan.nrrd", "2 NaN or Inf voxel values")


# ---------------------------------------------------------------- damaged files
@pytest.mark.parametrize("name", ["v.nii", "v.nii.gz"])
def test_truncated_nifti(tmp_path, name):
    """ITK would zero-fill a truncated NIfTI file silently; the loader must refuse it."""
    sitk.WriteImage(_image((20, 30, 40), np.int16), str(tmp_path / name))
    data = (tmp_path / name).read_bytes()
    (tmp_path / name).write_bytes(data[: len(data) * 2 // 3])
    expect_error(tmp_path / name, "truncated")


def test_truncated_nrrd_and_metaimage(tmp_path):
    for name in ("v.nrrd", "v.mha"):
        sitk.WriteImage(_image((20, 30, 40), np.int16), str(tmp_path / name), useCompression=False)
        data = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(data[: len(data) - 5000])
    expect_error(tmp_path / "v.nrrd", "SimpleITK cannot read it", "fread got only")
    expect_error(tmp_path / "v.mha", "truncated voxel data", "48000")


def test_metaimage_header_without_its_raw_file(tmp_path):
    sitk.WriteImage(_image((3, 4, 5)), str(tmp_path / "v.mhd"))
    (tmp_path / "v.raw").unlink()
    expect_error(tmp_path / "v.mhd", "data file 'v.raw'", "missing")


def test_metaimage_with_short_raw_file(tmp_path):
    sitk.WriteImage(_image((3, 4, 5)), str(tmp_path / "v.mhd"))
    (tmp_path / "v.raw").write_bytes(b"\x00" * 10)
    expect_error(tmp_path / "v.mhd", "truncated voxel data", name="v.raw")


def test_detached_nrrd_without_its_data_file(tmp_path):
    sitk.WriteImage(_image((3, 4, 5)), str(tmp_path / "v.nhdr"))
    data_file = next(p for p in tmp_path.iterdir() if p.suffix != ".nhdr")
    data_file.unlink()
    expect_error(tmp_path / "v.nhdr", f"data file '{data_file.name}'", "missing")


def test_vti_damaged_or_of_another_type_or_without_vtk(tmp_path, monkeypatch, capfd):
    pytest.importorskip("vtkmodules.vtkIOXML")
    from test_io import write_vti

    write_vti(tmp_path / "v.vti", np.zeros((3, 4, 5), np.float32))
    data = (tmp_path / "v.vti").read_bytes()
    (tmp_path / "cut.vti").write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    expect_error(tmp_path / "cut.vti", "VTK cannot read it", "XML")
    assert capfd.readouterr().err == ""  # VTK's own error print-out is captured, not shown

    (tmp_path / "poly.vti").write_text('<?xml version="1.0"?>\n<VTKFile type="PolyData" version="1.0"></VTKFile>\n')
    expect_error(tmp_path / "poly.vti", 'VTK XML "PolyData" file, not "ImageData"')

    monkeypatch.setitem(sys.modules, "vtkmodules.vtkIOXML", None)  # import now fails, as without VTK ...
    monkeypatch.setitem(sys.modules, "volsr_core._vtk", None)  # ... also when VolSR's VTK door was opened before
    expect_error(tmp_path / "v.vti", "reading .vti needs VTK: pip install 'volsr[vtk]'")


def test_series_uid_for_a_non_dicom_file(tmp_path):
    sitk.WriteImage(_image((3, 4, 5)), str(tmp_path / "v.nrrd"))
    expect_error(tmp_path / "v.nrrd", "applies only to DICOM", series_uid="1.2.3")


# ---------------------------------------------------------------- DICOM series problems
@pytest.fixture
def headsq_copy(headsq_dicom, tmp_path) -> Path:
    """A writable copy of the headsq series."""
    copy_series(headsq_dicom, tmp_path / "headsq")
    return tmp_path / "headsq"


def test_missing_slice(headsq_copy):
    by_position = files_by_position(headsq_copy)
    by_position[40].unlink()
    expect_error(
        headsq_copy, "non-uniform slice spacing (1.50-3.00 mm; 1 slice missing?",
        f"between {by_position[39].name} and {by_position[41].name}", "pass resample=True (CLI --resample)",
    )


def test_uneven_spacing_without_a_missing_slice(tmp_path):
    positions = np.array([[0, 0, z] for z in (0.0, 1.0, 2.0, 3.3, 4.3)])
    stored = np.zeros((5, 4, 4), np.int16)
    write_ct_series(tmp_path, stored, (1, 1), np.array([1, 0, 0, 0, 1, 0]), positions, list("abcde"))
    message = expect_error(tmp_path, "non-uniform slice spacing (1.00-1.30 mm;", "resample=True")
    assert "missing" not in message
    assert read_volume(tmp_path, resample=True).spacing[2] == pytest.approx(1.0)


def test_duplicate_slice_position(headsq_copy):
    ds = pydicom.dcmread(files_by_position(headsq_copy)[10])
    ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID = generate_uid()
    ds.save_as(headsq_copy / "zz_duplicate.dcm")
    for resample in (False, True):
        expect_error(headsq_copy, "two slices at one position", "zz_duplicate.dcm", "1 such pair", resample=resample)


def test_truncated_pixel_data_names_the_file(headsq_copy):
    victim = files_by_position(headsq_copy)[50]
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) - 3000])
    expect_error(headsq_copy, "cannot decode the pixel data", "less than expected", name=victim.name)


def test_a_header_cut_before_the_series_uid_is_named_not_ignored(headsq_copy):
    """Such a file belongs to no series: it used to be dropped silently as "non-DICOM"."""
    by_position = files_by_position(headsq_copy)
    victim = by_position[60]
    data = victim.read_bytes()
    victim.write_bytes(data[: data.index(b"\x20\x00\x0e\x00")])  # cut at (0020,000E) SeriesInstanceUID
    expect_error(headsq_copy, "DICOM file without SeriesInstanceUID", "CLI --resample", name=victim.name)
    record = read_volume(headsq_copy, resample=True)
    assert record.array.shape[0] == 93
    assert f"skipped 1 damaged file: {victim.name} (DICOM file without SeriesInstanceUID" in " ".join(record.notes)
    assert f"filled slice 60 between {by_position[59].name} and {by_position[61].name} (3 mm gap)" in record.notes[-1]


def test_resample_fills_the_slice_of_a_file_whose_pixel_data_is_cut(headsq_dicom, headsq_copy):
    whole = read_volume(headsq_dicom).array
    by_position = files_by_position(headsq_copy)
    victim = by_position[50]
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) - 3000])
    expect_error(headsq_copy, "cannot decode the pixel data", "CLI --resample", name=victim.name)
    record = read_volume(headsq_copy, resample=True)
    assert record.array.shape == whole.shape
    np.testing.assert_allclose(record.array[50], 0.5 * (whole[49] + whole[51]), atol=1e-3)
    np.testing.assert_array_equal(record.array[49], whole[49])
    assert "filled slice 50 between" in record.notes[-1]
    assert f"skipped 1 damaged file: {victim.name}" in record.notes[-2]


def test_header_cut_short_names_the_file(headsq_copy):
    """A file cut after its SeriesInstanceUID but before its geometry still belongs to the series."""
    victim = files_by_position(headsq_copy)[30]
    data = victim.read_bytes()
    victim.write_bytes(data[: data.index(b"\x20\x00\x32\x00")])  # cut at (0020,0032) ImagePositionPatient
    expect_error(headsq_copy, "lacks", "ImagePositionPatient", "damaged header", name=victim.name)


def test_mixed_slice_sizes(headsq_copy):
    victim = files_by_position(headsq_copy)[5]
    ds = pydicom.dcmread(victim)
    ds.PixelData = ds.pixel_array[:32, :32].tobytes()
    ds.Rows = ds.Columns = 32
    ds.save_as(victim)
    expect_error(headsq_copy, "mixed slice sizes", "32x32", victim.name, name="headsq")


def test_mixed_orientations(headsq_copy):
    victim = files_by_position(headsq_copy)[5]
    ds = pydicom.dcmread(victim)
    ds.ImageOrientationPatient = [1, 0, 0, 0, 0, -1]
    ds.save_as(victim)
    expect_error(headsq_copy, "mixed slice orientations", victim.name, name="headsq")


def test_multi_frame_is_refused(headsq_copy):
    victim = files_by_position(headsq_copy)[0]
    ds = pydicom.dcmread(victim)
    ds.NumberOfFrames = 2
    ds.save_as(victim)
    expect_error(headsq_copy, "multi-frame (enhanced) DICOM", name=victim.name)


def test_slice_without_position(headsq_copy):
    victim = files_by_position(headsq_copy)[3]
    ds = pydicom.dcmread(victim)
    del ds.ImagePositionPatient
    ds.save_as(victim)
    expect_error(headsq_copy, "lacks ImagePositionPatient", name=victim.name)


def test_orientation_that_is_not_orthonormal(tmp_path):
    positions = np.array([[0, 0, 2.0 * k] for k in range(3)])
    skewed = np.array([1, 0, 0, 0.5, 0.8, 0])
    write_ct_series(tmp_path, np.zeros((3, 4, 4), np.int16), (1, 1), skewed, positions, list("abc"))
    expect_error(tmp_path, "ImageOrientationPatient (1 0 0 0.5 0.8 0) is not two orthogonal unit vectors", name="a")


def test_gantry_tilt_is_refused(tmp_path):
    positions = np.array([[0, 0.8 * k, 2.0 * k] for k in range(4)])  # slides along y as z grows
    axial = np.array([1, 0, 0, 0, 1, 0])
    write_ct_series(tmp_path, np.zeros((4, 4, 4), np.int16), (1, 1), axial, positions, list("abcd"))
    expect_error(tmp_path, "drift 2.40 mm sideways", "gantry tilt")


def test_single_slice_series(headsq_copy, tmp_path):
    one = tmp_path / "one"
    one.mkdir()
    shutil.copy(files_by_position(headsq_copy)[0], one)
    expect_error(one, "single slice", "at least 2")


def test_unknown_series_uid_lists_the_available_ones(headsq_copy):
    other = as_new_series(files_by_position(headsq_copy)[:5], headsq_copy, "five")
    message = expect_error(
        headsq_copy, "no series with SeriesInstanceUID 1.2.3", other, "(93 files)", series_uid="1.2.3"
    )
    assert message.index("(93 files)") < message.index(other)  # largest first


def test_dcm_path_that_is_not_dicom(tmp_path):
    (tmp_path / "fake.dcm").write_text("I am text")
    with pytest.raises(InputError, match=r"fake\.dcm: content does not look like a DICOM file"):
        list_dicom_series(tmp_path / "fake.dcm")
