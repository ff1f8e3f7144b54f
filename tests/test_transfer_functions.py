"""Transfer functions: shipped presets, our JSON files, Slicer's presets.xml / .vp, vtkVolumeProperty."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from volsr_core.errors import InputError
from volsr_core.scene import (
    TransferFunction, get_preset, list_presets, load_presets, load_transfer_function,
    read_slicer_presets, read_vp_file, save_presets,
)

REQUIRED = ["CT-Bone", "CT-AAA", "CT-Cardiac", "CT-Chest-Contrast-Enhanced", "CT-Soft-Tissue",
            "MR-Default", "MR-Angio", "CT-Phantom"]
LIGHTING = ("shade", "ambient", "diffuse", "specular", "specular_power", "scalar_opacity_unit_distance")

# CT-AAA exactly as written in Slicer's presets.xml.
AAA_OPACITY = "12 -3024 0 143.556 0 166.222 0.686275 214.389 0.696078 419.736 0.833333 3071 0.803922"
AAA_GRADIENT = "4 0 1 255 1"
AAA_COLOR = ("24 -3024 0 0 0 143.556 0.615686 0.356863 0.184314 166.222 0.882353 0.603922 0.290196 "
             "214.389 1 1 1 419.736 1 0.937033 0.954531 3071 0.827451 0.658824 1")


def _slicer_xml(path: Path, **overrides: str) -> Path:
    """A one-entry presets.xml ('Test', CT-AAA's numbers) with attributes replaced by ``overrides``."""
    attrs = {"name": "Test", "interpolation": "1", "shade": "1", "ambient": "0.1", "diffuse": "0.9",
             "specular": "0.2", "specularPower": "10", "scalarOpacity": AAA_OPACITY,
             "gradientOpacity": AAA_GRADIENT, "colorTransfer": AAA_COLOR, **overrides}
    body = " ".join(f'{k}="{v}"' for k, v in attrs.items())
    path.write_text(f'<?xml version="1.0"?>\n<MRML>\n  <VolumeProperty {body}/>\n</MRML>\n')
    return path


def _vp(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


AAA_VP = ["1", "1", "0.9", "0.1", "0.2", "10", AAA_OPACITY, AAA_GRADIENT, AAA_COLOR]  # Slicer's .vp order


def _dense_grid(tf: TransferFunction, n: int = 1501) -> np.ndarray:
    """Values across the points and 25 % beyond each end (to exercise clamping)."""
    xs = np.concatenate([tf.color[:, 0], tf.scalar_opacity[:, 0]])
    lo, hi = xs.min(), xs.max()
    pad = 0.25 * max(hi - lo, 1.0)
    return np.linspace(lo - pad, hi + pad, n)


def _shipped() -> list[TransferFunction]:
    return [get_preset(name) for name in list_presets()]


def _assert_same(a: TransferFunction, b: TransferFunction) -> None:
    assert a.to_dict() == b.to_dict()


# shipped presets -----------------------------------------------------------------------------
def test_shipped_presets_cover_the_required_names_and_are_sane():
    names = list_presets()
    assert set(REQUIRED) <= set(names)
    assert len({n.lower() for n in names}) == len(names)
    for tf in _shipped():
        assert tf.shade and 0 < tf.ambient < 0.5 and 0.5 < tf.diffuse <= 1 and 5 <= tf.specular_power <= 50
        assert np.all((tf.color[:, 1:] >= 0) & (tf.color[:, 1:] <= 1))
        assert np.all((tf.scalar_opacity[:, 1] >= 0) & (tf.scalar_opacity[:, 1] <= 1))
        assert tf.metadata["modality"] in ("CT", "MR") and tf.metadata["description"]
        expected_range = (-1024.0, 3071.0) if tf.metadata["modality"] == "CT" else (0.0, 1000.0)
        assert tf.value_range == expected_range, tf.name
        if tf.metadata["modality"] == "MR":
            assert "normalised" in tf.metadata["units"]


def test_get_preset_is_case_insensitive_and_returns_independent_copies():
    a = get_preset("ct-bone")
    assert a.name == "CT-Bone"
    a.color[:, 1:] = 0.0
    assert get_preset("CT-BONE").color[:, 1:].max() > 0.5


def test_unknown_preset_lists_the_available_names():
    with pytest.raises(InputError) as info:
        get_preset("CT-Nonexistent")
    message = str(info.value)
    assert "CT-Nonexistent" in message and "CT-Phantom" in message and "MR-Angio" in message
    assert "\n" not in message


def test_ct_phantom_shows_skin_faintly_vessels_red_bone_white_and_hides_air_and_lungs():
    tf = get_preset("CT-Phantom")
    air_lungs_fat = tf.opacity_at(np.array([-1000.0, -850.0, -100.0]))
    assert np.all(air_lungs_fat == 0.0)
    skin = tf.opacity_at(np.array([40.0, 50.0, 60.0]))
    assert np.all((skin > 0) & (skin <= 0.02))
    vessels = tf.opacity_at(np.array([300.0, 350.0, 400.0]))
    assert np.all(vessels >= 0.5)
    bone = tf.opacity_at(np.array([700.0, 1000.0, 1300.0]))
    assert np.all(bone >= 0.9)
    r, g, b = tf.color_at(350.0)
    assert r > 0.8 and r > g + 0.3 and g >= b
    assert np.all(tf.color_at(np.array([700.0, 1000.0, 1300.0])) > 0.8)


# our JSON format -----------------------------------------------------------------------------
def test_every_shipped_preset_round_trips_through_to_dict_and_json_text():
    for tf in _shipped():
        _assert_same(TransferFunction.from_dict(json.loads(json.dumps(tf.to_dict()))), tf)


def test_save_and_load_presets_round_trip_exactly_and_leave_no_temp_files(tmp_path: Path):
    path = tmp_path / "mine.json"
    path.write_text("old contents")
    save_presets(path, _shipped())
    loaded = load_presets(path)
    assert list(loaded) == list_presets()
    for tf in _shipped():
        _assert_same(loaded[tf.name], tf)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.json"]


def test_save_presets_names_from_a_mapping_and_refuses_duplicates(tmp_path: Path):
    bone = get_preset("CT-Bone")
    save_presets(tmp_path / "a.json", {"My-Bone": bone})
    assert list(load_presets(tmp_path / "a.json")) == ["My-Bone"]
    with pytest.raises(ValueError, match="distinct"):
        save_presets(tmp_path / "b.json", {"x": bone, "X": bone})
    assert not (tmp_path / "b.json").exists()


def test_load_transfer_function_reads_every_kind(tmp_path: Path):
    presets = tmp_path / "presets.json"
    save_presets(presets, _shipped())
    assert load_transfer_function(presets).name == list_presets()[0]
    _assert_same(load_transfer_function(presets, "ct-phantom"), get_preset("CT-Phantom"))

    single = tmp_path / "single.json"
    single.write_text(json.dumps(get_preset("MR-Angio").to_dict()))
    _assert_same(load_transfer_function(single), get_preset("MR-Angio"))
    with pytest.raises(InputError, match="MR-Angio"):
        load_transfer_function(single, "CT-Bone")

    xml = _slicer_xml(tmp_path / "presets.xml")
    assert load_transfer_function(xml).name == "Test"
    assert load_transfer_function(xml, "TEST").name == "Test"
    with pytest.raises(InputError, match="available: Test"):
        load_transfer_function(xml, "other")

    vp = _vp(tmp_path / "aaa.vp", AAA_VP)
    assert load_transfer_function(vp).name == "aaa"
    with pytest.raises(InputError, match="'aaa'"):
        load_transfer_function(vp, "CT-AAA")


def test_load_transfer_function_tells_kinds_without_a_known_suffix(tmp_path: Path):
    for stem, source in (("a", _vp(tmp_path / "a.vp", AAA_VP)), ("b", _slicer_xml(tmp_path / "b.xml"))):
        sniffed = tmp_path / f"{stem}.txt"
        sniffed.write_text(source.read_text())
        assert load_transfer_function(sniffed).to_dict() == load_transfer_function(source).to_dict()
    empty = tmp_path / "empty.json"
    save_presets(empty, [])
    assert load_presets(empty) == {}
    with pytest.raises(InputError, match="holds no presets"):
        load_transfer_function(empty)
    presets = tmp_path / "presets.dat"
    save_presets(presets, [get_preset("CT-Lung")])
    _assert_same(load_transfer_function(presets), get_preset("CT-Lung"))


# Slicer --------------------------------------------------------------------------------------
def test_every_slicer_preset_loads_with_sane_contents(shared_data: Path):
    presets = read_slicer_presets(shared_data / "slicer-presets.xml")
    assert len(presets) >= 25
    for name in ("CT-AAA", "CT-Bone", "CT-Cardiac", "MR-Default", "MR-Angio", "CT-X-ray"):
        assert name in presets
    for name, tf in presets.items():
        assert tf.name == name
        assert len(tf.scalar_opacity) >= 2, name
        assert np.all((tf.color[:, 1:] >= 0) & (tf.color[:, 1:] <= 1)), name
        assert np.all((tf.scalar_opacity[:, 1] >= 0) & (tf.scalar_opacity[:, 1] <= 1)), name
        assert tf.metadata["interpolation"] == "linear"


def test_slicer_ct_aaa_numbers_match_the_xml_text(shared_data: Path):
    tf = read_slicer_presets(shared_data / "slicer-presets.xml")["CT-AAA"]
    np.testing.assert_array_equal(tf.scalar_opacity, [[-3024, 0], [143.556, 0], [166.222, 0.686275],
                                                      [214.389, 0.696078], [419.736, 0.833333],
                                                      [3071, 0.803922]])
    np.testing.assert_array_equal(tf.gradient_opacity, [[0, 1], [255, 1]])
    np.testing.assert_array_equal(tf.color[3], [214.389, 1, 1, 1])
    np.testing.assert_array_equal(tf.color[-1], [3071, 0.827451, 0.658824, 1])
    assert (tf.shade, tf.ambient, tf.diffuse, tf.specular, tf.specular_power) == (True, 0.1, 0.9, 0.2, 10.0)
    assert tf.metadata["effective_range"] == [143.556, 419.736]
    assert not tf.has_gradient_opacity


def test_slicer_effective_range_is_dropped_when_unset_or_malformed(shared_data: Path):
    presets = read_slicer_presets(shared_data / "slicer-presets.xml")
    assert "effective_range" not in presets["uCT-Bone-8bit"].metadata  # "0 -1": unset
    assert "effective_range" not in presets["CT-X-ray"].metadata  # "-250.0.0 1550.0" in Slicer's file


def test_vp_file_agrees_with_the_same_numbers_in_xml(tmp_path: Path):
    from_xml = read_slicer_presets(_slicer_xml(tmp_path / "p.xml"))["Test"]
    from_vp = read_vp_file(_vp(tmp_path / "Test.vp", AAA_VP))
    _assert_same(from_vp, TransferFunction.from_dict({**from_xml.to_dict(), "metadata": from_vp.metadata}))
    assert (from_vp.ambient, from_vp.diffuse) == (0.1, 0.9)  # .vp stores diffuse before ambient


def test_vp_empty_lines_keep_defaults_and_an_empty_gradient_gives_none(tmp_path: Path):
    lines = ["", "", "", "", "", "", AAA_OPACITY, "", AAA_COLOR]
    tf = read_vp_file(_vp(tmp_path / "sparse.vp", lines))
    defaults = TransferFunction(color=[[0, 0, 0, 0]], scalar_opacity=[[0, 0]])
    assert tf.gradient_opacity is None
    assert [getattr(tf, k) for k in LIGHTING] == [getattr(defaults, k) for k in LIGHTING]


# bad files -----------------------------------------------------------------------------------
def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _bad_json(folder: Path, text: str) -> Path:
    return _write(folder / "bad.json", text)


BAD_FILES = {
    "json-syntax": (lambda d: _bad_json(d, '{"format": "volsr-presets",'), load_presets, "not valid JSON"),
    "json-format": (lambda d: _bad_json(d, '{"format": "other", "version": 1, "presets": []}'),
                    load_presets, "not a VolSR presets file"),
    "json-version": (lambda d: _bad_json(d, '{"format": "volsr-presets", "version": 9, "presets": []}'),
                     load_presets, "version 9"),
    "json-shape": (lambda d: _bad_json(d, '{"format": "volsr-presets", "version": 1, "presets": '
                                          '[{"name": "x", "color": [[0, 1, 1]], "scalar_opacity": [[0, 0]]}]}'),
                   load_presets, "preset #1"),
    "json-key": (lambda d: _bad_json(d, '{"format": "volsr-presets", "version": 1, "presets": '
                                        '[{"name": "x", "colour": [[0, 1, 1, 1]], "scalar_opacity": [[0, 0]]}]}'),
                 load_presets, "colour"),
    "json-empty": (lambda d: _bad_json(d, '{"format": "volsr-presets", "version": 1, "presets": [{}]}'),
                   load_presets, "preset #1: transfer function lacks"),
    "json-missing": (lambda d: d / "absent.json", load_presets, "no such file"),
    "xml-count": (lambda d: _slicer_xml(d / "bad.xml", scalarOpacity="6 0 0 100 1"),
                  read_slicer_presets, "preset 'Test': scalarOpacity count says 6 values but 4 follow"),
    "xml-odd": (lambda d: _slicer_xml(d / "bad.xml", colorTransfer="6 0 0 0 0 1 1"),
                read_slicer_presets, "preset 'Test': colorTransfer has 6 values, not a multiple of 4"),
    "xml-number": (lambda d: _slicer_xml(d / "bad.xml", ambient="lots"), read_slicer_presets,
                   "preset 'Test': ambient is not a number"),
    "xml-missing": (lambda d: _slicer_xml(d / "bad.xml", colorTransfer=""), read_slicer_presets,
                    "preset 'Test': lacks colorTransfer"),
    "xml-syntax": (lambda d: _write(d / "bad.xml", "<MRML><VolumeProperty"), read_slicer_presets, "not valid XML"),
    "xml-empty": (lambda d: _write(d / "bad.xml", "<MRML/>"), read_slicer_presets, "no VolumeProperty"),
    "vp-short": (lambda d: _vp(d / "short.vp", AAA_VP[:5]), read_vp_file, "this one has 5"),
    "vp-count": (lambda d: _vp(d / "bad.vp", AAA_VP[:8] + ["8 0 0 0 0 1 1 1"]), read_vp_file,
                 "preset 'bad': colorTransfer count says 8 values but 7 follow"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_files_give_one_line_input_errors_naming_the_file(tmp_path: Path, case: str):
    make, reader, expected = BAD_FILES[case]
    path = make(tmp_path)
    with pytest.raises(InputError) as info:
        reader(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    assert expected in message
    with pytest.raises(InputError):  # the generic loader reports the same files the same way
        load_transfer_function(path)


# evaluation and placement --------------------------------------------------------------------
def test_placed_on_maps_value_range_onto_the_target():
    tf = get_preset("CT-Phantom")
    placed = tf.placed_on(0.0, 255.0)
    assert placed.value_range == (0.0, 255.0)
    hu = np.linspace(-1500.0, 3500.0, 777)
    (lo, hi) = tf.value_range
    same_position = (hu - lo) / (hi - lo) * 255.0
    np.testing.assert_allclose(placed.color_at(same_position), tf.color_at(hu), atol=1e-12)
    np.testing.assert_allclose(placed.opacity_at(same_position), tf.opacity_at(hu), atol=1e-12)


def test_rescaling_scales_gradient_magnitudes_by_the_same_factor():
    tf = get_preset("CT-Bone")
    placed = tf.placed_on(0.0, 4095.0 / 16.0)  # factor 1/16
    g = np.linspace(0.0, 4000.0, 101)
    np.testing.assert_allclose(placed.gradient_opacity_at(g / 16.0), tf.gradient_opacity_at(g), atol=1e-12)


# VTK -----------------------------------------------------------------------------------------
def test_core_modules_import_without_loading_vtk():
    code = ("import sys, volsr_core.scene, volsr_core.scene.presets, volsr_core.scene.slicer_presets; "
            "sys.exit(any(m.startswith(('vtk', 'vtkmodules')) for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


@pytest.fixture(scope="module")
def vtk_bridge():
    pytest.importorskip("vtkmodules.vtkRenderingCore")
    from volsr_core.scene import vtk_bridge
    return vtk_bridge


def _assert_matches_vtk(tf: TransferFunction, prop) -> None:
    """Our evaluation equals VTK's GetColor/GetValue on a dense grid, clamped ends included."""
    xs = _dense_grid(tf)
    color, opacity, gradient = (prop.GetRGBTransferFunction(0), prop.GetScalarOpacity(0),
                                prop.GetGradientOpacity(0))
    np.testing.assert_allclose(tf.color_at(xs), [color.GetColor(x) for x in xs], atol=1e-6, err_msg=tf.name)
    np.testing.assert_allclose(tf.opacity_at(xs), [opacity.GetValue(x) for x in xs], atol=1e-6, err_msg=tf.name)
    gs = np.linspace(-10.0, 4000.0, 801)
    np.testing.assert_allclose(tf.gradient_opacity_at(gs), [gradient.GetValue(g) for g in gs], atol=1e-6,
                               err_msg=tf.name)
    lighting = (prop.GetShade(0), prop.GetAmbient(0), prop.GetDiffuse(0), prop.GetSpecular(0),
                prop.GetSpecularPower(0), prop.GetScalarOpacityUnitDistance(0))
    assert lighting == pytest.approx(tuple(float(getattr(tf, k)) for k in LIGHTING))
    assert prop.GetInterpolationType() == 1  # VTK_LINEAR_INTERPOLATION


@pytest.mark.vtk
def test_every_shipped_preset_round_trips_through_vtk_volume_property(vtk_bridge):
    for tf in _shipped():
        prop = vtk_bridge.to_vtk_volume_property(tf)
        _assert_matches_vtk(tf, prop)
        back = vtk_bridge.from_vtk_volume_property(prop, name=tf.name)
        np.testing.assert_array_equal(back.color, tf.color)
        np.testing.assert_array_equal(back.scalar_opacity, tf.scalar_opacity)
        if tf.has_gradient_opacity:
            np.testing.assert_array_equal(back.gradient_opacity, tf.gradient_opacity)
        else:
            assert back.gradient_opacity is None
        assert [getattr(back, k) for k in LIGHTING] == pytest.approx([getattr(tf, k) for k in LIGHTING])
        assert back.name == tf.name


@pytest.mark.vtk
def test_every_slicer_preset_evaluates_like_vtk(vtk_bridge, shared_data: Path):
    for tf in read_slicer_presets(shared_data / "slicer-presets.xml").values():
        _assert_matches_vtk(tf, vtk_bridge.to_vtk_volume_property(tf))


@pytest.mark.vtk
def test_evaluation_matches_vtk_functions_with_steps_and_clamping(vtk_bridge):
    tf = TransferFunction(color=[[-100, 0.2, 0.4, 0.6], [0, 1, 0, 0], [50, 0, 1, 0], [200, 0.1, 0.1, 0.9]],
                          scalar_opacity=[[-100, 0.1], [10, 0.1], [10, 0.8], [300, 0.3]],
                          gradient_opacity=[[5, 0.0], [25, 1.0]])
    prop = vtk_bridge.to_vtk_volume_property(tf)
    _assert_matches_vtk(tf, prop)
    opacity, color = prop.GetScalarOpacity(0), prop.GetRGBTransferFunction(0)
    assert opacity.GetValue(9.999) == pytest.approx(0.1) and opacity.GetValue(10.001) == pytest.approx(0.8, abs=1e-4)
    np.testing.assert_allclose(tf.color_at(np.array([-1e6, 1e6])), [color.GetColor(-1e6), color.GetColor(1e6)])
    assert tf.gradient_opacity_at(0.0) == 0.0 == prop.GetGradientOpacity(0).GetValue(0.0)


@pytest.mark.vtk
def test_vtk_default_and_constant_gradient_opacity_read_back_as_none(vtk_bridge):
    base = get_preset("CT-AAA")
    assert base.gradient_opacity is None
    prop = vtk_bridge.to_vtk_volume_property(base)
    assert not prop.HasGradientOpacity(0)  # VTK's own default is left in place
    assert vtk_bridge.from_vtk_volume_property(prop).gradient_opacity is None
    constant = TransferFunction.from_dict({**base.to_dict(), "gradient_opacity": [[0, 1], [255, 1]]})
    assert vtk_bridge.from_vtk_volume_property(
        vtk_bridge.to_vtk_volume_property(constant)).gradient_opacity is None


@pytest.mark.vtk
def test_grey_vtk_transfer_function_reads_as_equal_rgb(vtk_bridge):
    from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
    from vtkmodules.vtkRenderingCore import vtkVolumeProperty

    grey = vtkPiecewiseFunction()
    grey.AddPoint(0.0, 0.25)
    grey.AddPoint(100.0, 0.75)
    prop = vtkVolumeProperty()
    prop.SetColor(grey)
    prop.SetScalarOpacity(grey)
    tf = vtk_bridge.from_vtk_volume_property(prop, name="grey")
    np.testing.assert_array_equal(tf.color, [[0, 0.25, 0.25, 0.25], [100, 0.75, 0.75, 0.75]])


@pytest.mark.vtk
def test_non_linear_vtk_segments_are_refused(vtk_bridge):
    prop = vtk_bridge.to_vtk_volume_property(get_preset("CT-Bone"))
    prop.GetScalarOpacity(0).AddPoint(100.0, 0.5, 0.3, 0.0)  # midpoint 0.3
    with pytest.raises(ValueError, match="midpoint"):
        vtk_bridge.from_vtk_volume_property(prop)


def test_place_on_volume_keeps_hu_presets_on_hu_volumes_and_moves_them_otherwise():
    import numpy as np

    from volsr_core.scene import Volume
    from volsr_core.scene.presets import place_on_volume

    tf = get_preset("CT-Bone")
    ct = Volume(np.linspace(-1000, 2000, 4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6), modality="CT", units="HU")
    rescaled = Volume(np.linspace(0, 255, 4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6))
    assert place_on_volume(tf, ct).to_dict() == tf.to_dict()
    assert place_on_volume(tf, rescaled, None).to_dict() == tf.to_dict()
    assert place_on_volume(tf, rescaled, "none").to_dict() == tf.to_dict()
    auto = place_on_volume(tf, rescaled)
    assert auto.value_range == pytest.approx(rescaled.percentiles())
    assert place_on_volume(tf, rescaled, (10.0, 200.0)).value_range == (10.0, 200.0)
