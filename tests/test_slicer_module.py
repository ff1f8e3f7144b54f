"""The 3D Slicer extension (CMakeLists.txt, VolSRModule/) and its Slicer-free core (volsr_core.hosts.slicer).

Slicer itself is not here: the module's files are checked against Slicer's templates, VolSR.py is
compiled and imported as plain Python (its parameter node, its logic's way of following it and its
VolSRLib.bootstrap helper run without Slicer), and the core runs through the real VTK adapter in an
offscreen (EGL) VTK window holding a scene in RAS terms, as Slicer's 3D view holds it.
"""
from __future__ import annotations

import ast
import dataclasses
import json
import py_compile
import re
import subprocess
import sys
import typing
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from volsr_core.io import make_phantom
from volsr_core.scene import Camera, Volume

REPO = Path(__file__).resolve().parents[1]
MODULE = REPO / "VolSRModule"
VOLSR_PY = MODULE / "VolSR.py"
BOOTSTRAP_PY = MODULE / "VolSRLib" / "bootstrap.py"
UI = MODULE / "Resources" / "UI" / "VolSR.ui"
W, H = 128, 96


def cmake_text(path: Path) -> str:
    """A CMake file without comments, whitespace collapsed."""
    lines = [line.split("#", 1)[0] for line in path.read_text(encoding="utf-8").splitlines()]
    return " ".join(" ".join(lines).split())


# the extension's files -----------------------------------------------------------------------------------
def test_the_top_level_cmakelists_is_slicers_extension_template():
    text = cmake_text(REPO / "CMakeLists.txt")
    order = ["cmake_minimum_required(", "project(VolSR)", "find_package(Slicer REQUIRED)", "include(${Slicer_USE_FILE})",
             "add_subdirectory(VolSRModule)", "include(${Slicer_EXTENSION_GENERATE_CONFIG})",
             "include(${Slicer_EXTENSION_CPACK})"]
    positions = [text.find(item) for item in order]
    assert -1 not in positions, f"missing: {[o for o, p in zip(order, positions) if p < 0]}"
    assert positions == sorted(positions), "template order: project, meta-information, find_package, modules, CPack"
    for key in ("HOMEPAGE", "CATEGORY", "CONTRIBUTORS", "DESCRIPTION", "ICONURL", "SCREENSHOTURLS", "DEPENDS"):
        assert re.search(rf"set\(EXTENSION_{key} \S", text), f"EXTENSION_{key} is not set"
    assert text.find("set(EXTENSION_HOMEPAGE") < positions[2], "meta-information comes before find_package"


def test_the_module_cmakelists_builds_a_scripted_module_with_its_resources_and_tests():
    text = cmake_text(MODULE / "CMakeLists.txt")
    assert "set(MODULE_NAME VolSR)" in text
    scripts = re.search(r"set\(MODULE_PYTHON_SCRIPTS ([^)]*)\)", text).group(1).split()
    resources = re.search(r"set\(MODULE_PYTHON_RESOURCES ([^)]*)\)", text).group(1).split()
    files = [s.replace("${MODULE_NAME}", "VolSR") for s in scripts + resources]
    assert "VolSR.py" in files and "Resources/UI/VolSR.ui" in files and "Resources/Icons/VolSR.png" in files
    assert "Resources/requirements.txt" in files
    assert "VolSRLib/__init__.py" in files and "VolSRLib/bootstrap.py" in files, "the helper package is installed"
    for name in files:
        assert (MODULE / name).is_file(), f"{name} is listed but missing"
    python = {str(f.relative_to(MODULE)) for f in MODULE.rglob("*.py") if "Testing" not in f.parts}
    assert python <= set(files), f"Python files Slicer would not install: {sorted(python - set(files))}"
    macro = re.search(r"slicerMacroBuildScriptedModule\(([^)]*)\)", text).group(1)
    for part in ("NAME ${MODULE_NAME}", "SCRIPTS ${MODULE_PYTHON_SCRIPTS}", "RESOURCES ${MODULE_PYTHON_RESOURCES}",
                 "WITH_GENERIC_TESTS"):
        assert part in macro
    testing = re.search(r"if\(BUILD_TESTING\)(.*)endif\(\)", text).group(1)
    assert "slicer_add_python_unittest(SCRIPT ${MODULE_NAME}.py)" in testing and "add_subdirectory(Testing)" in testing
    assert "add_subdirectory(Python)" in cmake_text(MODULE / "Testing" / "CMakeLists.txt")
    assert (MODULE / "Testing" / "Python" / "CMakeLists.txt").is_file()


def ui_bindings() -> dict[str, tuple[str, str]]:
    """VolSR.ui's widgets bound to a parameter (dynamic property SlicerParameterName): parameter -> (name, class)."""
    bound = {}
    for widget in ET.parse(UI).getroot().iter("widget"):
        prop = widget.find("property[@name='SlicerParameterName']")
        if prop is not None:
            assert prop.get("stdset") == "0", "SlicerParameterName is a dynamic property (stdset=0)"
            bound[prop.findtext("string")] = (widget.get("name"), widget.get("class"))
    return bound


def widget_names_used_by_the_module() -> set[str]:
    """Widgets VolSR.py names, and those bound to its parameter node (connectGui)."""
    named = set(re.findall(r"self\.ui\.(\w+)", VOLSR_PY.read_text(encoding="utf-8")))
    return named | {name for name, _ in ui_bindings().values()}


def test_the_ui_file_is_designer_xml_with_every_widget_the_module_uses():
    root = ET.parse(UI).getroot()
    assert root.tag == "ui" and root.findtext("class") == "VolSR"
    top = root.find("widget")
    assert top.get("class") == "qMRMLWidget" and top.get("name") == "VolSR"
    widgets = {w.get("name"): w.get("class") for w in root.iter("widget")}
    used = widget_names_used_by_the_module()
    assert used >= {"inputSelector", "presetComboBox", "scaleComboBox", "variantComboBox", "enableCheckBox",
                    "frameTimeLabel"}
    assert not used - set(widgets), f"VolSR.py uses widgets the UI lacks: {sorted(used - set(widgets))}"
    assert widgets["inputSelector"] == "qMRMLNodeComboBox"
    node_types = [s.text for s in root.find(".//widget[@name='inputSelector']/property[@name='nodeTypes']").iter("string")]
    assert node_types == ["vtkMRMLScalarVolumeNode"]
    assert widgets["enableCheckBox"] in ("QCheckBox", "QPushButton") and widgets["frameTimeLabel"] == "QLabel"

    def items(name):
        return [i.findtext("property/string") for i in root.find(f".//widget[@name='{name}']").findall("item")]

    assert items("scaleComboBox") == ["2", "4", "8"] and items("variantComboBox") == ["XS", "S", "M", "L"]
    declared = {c.findtext("class") for c in root.iter("customwidget")}
    custom = {c for c in widgets.values() if not c.startswith("Q")}
    assert custom <= declared, f"custom widgets not declared: {sorted(custom - declared)}"
    scene = [c for c in root.iter("connection") if c.findtext("receiver") == "inputSelector"]
    assert scene and scene[0].findtext("slot") == "setMRMLScene(vtkMRMLScene*)"


def test_the_icon_is_a_128_pixel_png():
    from PIL import Image

    path = MODULE / "Resources" / "Icons" / "VolSR.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(path) as icon:
        assert icon.format == "PNG" and icon.size == (128, 128)


def install_requires() -> list[str]:
    tree = ast.parse((REPO / "setup.py").read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == "install_requires":
            return [ast.literal_eval(e) for e in node.value.elts]
    raise AssertionError("setup.py has no install_requires")


@pytest.fixture
def volsr(monkeypatch):
    """VolSR.py imported as plain Python (outside Slicer its Slicer classes get stand-in bases), its folder
    on sys.path as Slicer puts it there (for VolSRLib)."""
    import importlib.util

    monkeypatch.syspath_prepend(str(MODULE))
    spec = importlib.util.spec_from_file_location("VolSR_outside_slicer", VOLSR_PY)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_requirements_txt_lists_the_core_dependencies_but_not_slicers_own(volsr):
    boot = volsr.bootstrap
    specs = boot.requirementLines()
    names = {boot.requirementName(s) for s in specs}
    slicer_brings = {"vtk", "simpleitk", "numpy"}
    assert not names & (slicer_brings | {"torch"}), f"must not be installed into Slicer: {names & slicer_brings}"
    wanted = {boot.requirementName(s) for s in install_requires()} - slicer_brings
    assert wanted <= names, f"setup.py needs, requirements.txt lacks: {sorted(wanted - names)}"
    assert {"onnxruntime", "numba", "pydicom", "h5py"} <= names
    assert boot.requirementName("PyYAML>=6.0") == "pyyaml" and boot.requirementName("numba-cuda>=0.2") == "numba-cuda"


def top_level_imports(tree: ast.Module) -> set[str]:
    """The packages a module imports in statements directly in its body (not inside functions, try or if)."""
    names = {a.name.split(".")[0] for n in tree.body if isinstance(n, ast.Import) for a in n.names}
    return names | {n.module.split(".")[0] for n in tree.body if isinstance(n, ast.ImportFrom) and n.module}


def test_volsr_py_compiles_and_defines_the_four_template_classes(tmp_path):
    py_compile.compile(str(VOLSR_PY), cfile=str(tmp_path / "VolSR.pyc"), doraise=True)
    tree = ast.parse(VOLSR_PY.read_text(encoding="utf-8"))
    classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
    for name, base in (("VolSR", "ScriptedLoadableModule"), ("VolSRWidget", "ScriptedLoadableModuleWidget"),
                       ("VolSRLogic", "ScriptedLoadableModuleLogic"), ("VolSRTest", "ScriptedLoadableModuleTest")):
        assert name in classes, f"{name} is missing"
        assert base in [b.id for b in classes[name].bases if isinstance(b, ast.Name)]

    def methods(name):
        return {n.name for n in classes[name].body if isinstance(n, ast.FunctionDef)}

    assert {"setup", "cleanup"} <= methods("VolSRWidget")
    assert {"enable", "disable", "ensureDependencies", "volumeFromNode", "frameTimeMs"} <= methods("VolSRLogic")
    assert {"setUp", "runTest"} <= methods("VolSRTest")
    # qt and ctk only inside functions; slicer only inside the try that gives stand-ins outside Slicer
    assert not top_level_imports(tree) & {"qt", "ctk", "slicer", "vtk", "volsr_core"}

    # Slicer's template (5.2+): a parameter node wrapper; observers through VTKObservationMixin
    decorators = [d.id for d in classes["VolSRParameterNode"].decorator_list if isinstance(d, ast.Name)]
    assert decorators == ["parameterNodeWrapper"]
    for name in ("VolSRWidget", "VolSRLogic"):
        assert "VTKObservationMixin" in [b.id for b in classes[name].bases if isinstance(b, ast.Name)]
    assert {"initializeParameterNode", "setParameterNode", "onParameterNodeModified", "onSceneStartClose",
            "onSceneEndClose", "enter", "exit"} <= methods("VolSRWidget")
    assert {"getParameterNode", "apply", "cleanup"} <= methods("VolSRLogic")
    assert {"test_ras_to_lps", "test_parameter_node", "test_VolSR_draws_the_3D_view"} <= methods("VolSRTest")
    # the parameter node wrapper reads the class's annotations as objects: no postponed (string) annotations
    assert not any(isinstance(n, ast.ImportFrom) and n.module == "__future__" for n in tree.body)
    # the pip bootstrap lives in VolSRLib/bootstrap.py, not at the top of VolSR.py
    assert "bootstrap" in [a.name for n in tree.body if isinstance(n, ast.ImportFrom) and n.module == "VolSRLib"
                           for a in n.names]
    assert not {"requirementLines", "missingRequirements", "importVolsrCore"} & {
        n.name for n in tree.body if isinstance(n, ast.FunctionDef)}


def test_the_bootstrap_helper_compiles_and_needs_slicer_only_to_install(tmp_path):
    py_compile.compile(str(BOOTSTRAP_PY), cfile=str(tmp_path / "bootstrap.pyc"), doraise=True)
    tree = ast.parse(BOOTSTRAP_PY.read_text(encoding="utf-8"))
    assert not top_level_imports(tree) & {"qt", "ctk", "slicer", "vtk", "volsr_core"}
    functions = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert {"requirementLines", "requirementName", "missingRequirements", "sourceCheckout", "importVolsrCore",
            "ensureDependencies"} <= set(functions)
    uses_slicer = {name for name, f in functions.items()
                   for n in ast.walk(f) if isinstance(n, ast.Import) and any(a.name == "slicer" for a in n.names)}
    assert uses_slicer == {"ensureDependencies"}


def test_the_bootstrap_helper_works_outside_slicer(volsr, tmp_path):
    boot = volsr.bootstrap
    assert boot.REQUIREMENTS == MODULE / "Resources" / "requirements.txt" and boot.MODULE_DIR == MODULE
    requirements = tmp_path / "requirements.txt"
    requirements.write_text("# comment\n\npytest>=7  # the test runner\nsurely-not-installed_pkg[extra]>=1\n")
    specs = boot.requirementLines(requirements)
    assert specs == ["pytest>=7", "surely-not-installed_pkg[extra]>=1"]
    assert boot.missingRequirements(specs) == ["surely-not-installed_pkg[extra]>=1"]
    assert boot.requirementName(specs[1]) == "surely-not-installed-pkg"
    assert boot.sourceCheckout() == REPO and boot.sourceCheckout(tmp_path / "VolSRModule") is None
    assert boot.importVolsrCore().__name__ == "volsr_core"
    with pytest.raises(ImportError):  # installing needs Slicer's pip helpers
        boot.ensureDependencies()


def test_volsr_py_imports_outside_slicer_and_finds_volsr_core_in_its_checkout(tmp_path):
    """Without an installed volsr, the module's bootstrap puts its checkout on sys.path (presets and models
    included)."""
    code = f"""
import sys, importlib.util, json
sys.meta_path = [f for f in sys.meta_path if 'Editable' not in getattr(f, '__name__', type(f).__name__)]
sys.path = [p for p in sys.path if p not in ('', '.', {str(REPO)!r})]
try:
    import volsr_core
    raise SystemExit('volsr_core is importable without the checkout: the test cannot show anything')
except ImportError:
    pass
sys.path.insert(0, {str(MODULE)!r})  # as Slicer puts the module's folder there
spec = importlib.util.spec_from_file_location('VolSR', {str(VOLSR_PY)!r})
VolSR = importlib.util.module_from_spec(spec); spec.loader.exec_module(VolSR)
assert VolSR.slicer is None
core = VolSR.bootstrap.importVolsrCore()
from volsr_core.scene.presets import get_preset
from volsr_core.runtime.models import models_dir
print(json.dumps({{"core": core.__file__, "preset": get_preset("CT-Bone").name, "models": str(models_dir()),
                   "presets": list(VolSR.PRESETS), "checkout": str(VolSR.bootstrap.sourceCheckout())}}))
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert result.returncode == 0, result.stdout + result.stderr
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert Path(out["core"]).resolve() == REPO / "volsr_core" / "__init__.py"
    assert Path(out["checkout"]) == REPO and Path(out["models"]).resolve() == REPO / "resources" / "models"
    assert out["preset"] == "CT-Bone" and "CT-AAA" in out["presets"]


# the parameter node ---------------------------------------------------------------------------------------
def test_the_parameter_node_declares_every_setting_the_ui_binds(volsr):
    """Each widget with a SlicerParameterName binds to a declared setting of a type Slicer's connectors take
    for that widget (QComboBox: Annotated[int | str, Choice]; QCheckBox: bool; qMRMLNodeComboBox: a node
    class); the model path is bound by hand (ctkPathLineEdit binds only to pathlib.Path)."""
    node_class = volsr.VolSRParameterNode
    hints = typing.get_type_hints(node_class, include_extras=True)  # objects, without the module's globals
    assert set(hints) == {"inputVolume", "preset", "scale", "variant", "device", "modelPath", "enabled"}
    bound = ui_bindings()
    assert set(bound) == set(hints) - {"modelPath"}, "every setting but the model path is bound in VolSR.ui"
    root = ET.parse(UI).getroot()
    for name, (widget, widget_class) in bound.items():
        kind = hints[name]
        if widget_class == "QComboBox":
            assert typing.get_origin(kind) is typing.Annotated, f"{name}: a QComboBox needs Annotated[..., Choice]"
            base, *extras = typing.get_args(kind)
            choices = [e.choices for e in extras if isinstance(e, volsr.Choice)]
            assert base in (int, str) and len(choices) == 1, f"{name}: {kind}"
            assert getattr(node_class, name) in choices[0], f"{name}: the default is one of the choices"
            assert all(isinstance(c, base) for c in choices[0])
            items = [i.findtext("property/string") for i in root.find(f".//widget[@name='{widget}']").findall("item")]
            assert not items or items == [str(c) for c in choices[0]], f"{widget}: its items are the choices"
        elif widget_class == "QCheckBox":
            assert kind is bool
        else:
            assert widget_class == "qMRMLNodeComboBox" and kind is volsr.vtkMRMLScalarVolumeNode
            types = [t.text for t in root.find(f".//widget[@name='{widget}']/property[@name='nodeTypes']").iter("string")]
            assert types == [kind.__name__]
    assert hints["modelPath"] is str
    assert re.search(r'self\.ui\.modelPathLineEdit\.connect\("currentPathChanged\(QString\)", self\.onModelPathChanged\)',
                     VOLSR_PY.read_text(encoding="utf-8"))
    defaults = {name: getattr(node_class, name, None) for name in hints}
    assert defaults == {"inputVolume": None, "preset": volsr.KEEP_PRESET, "scale": 2, "variant": "XS", "device": "cpu",
                        "modelPath": "", "enabled": False}
    preset_choices = typing.get_args(hints["preset"])[1].choices
    assert tuple(preset_choices) == (volsr.KEEP_PRESET, *volsr.PRESETS)


def test_the_module_settings_are_volsr_cores(volsr):
    """PRESETS, SCALES, VARIANTS, DEVICES and the default scale and variant are spelled out in VolSR.py
    (needed before volsr_core can be imported): they must stay volsr_core's."""
    from volsr_core.hosts.slicer import SCALES, VARIANTS, preset_names
    from volsr_core.render.raycaster import DEVICES
    from volsr_core.runtime.models import DEFAULT_SCALE, default_variant

    assert list(volsr.PRESETS) == preset_names()
    assert volsr.SCALES == SCALES and volsr.VARIANTS == VARIANTS and volsr.DEVICES == DEVICES
    defaults = volsr.VolSRParameterNode()
    assert (defaults.scale, defaults.variant) == (DEFAULT_SCALE, default_variant(DEFAULT_SCALE)) == (2, "XS")


def test_the_logic_follows_the_parameter_node(volsr):
    """VolSRLogic.apply: the preset is written once per (volume, preset); VolSR starts, restarts on a changed
    setting and stops as the parameter node says; what it could not switch on is unticked. Slicer's part
    (enable, disable, applyPreset) is replaced by recorders."""
    logic = volsr.VolSRLogic()
    calls = []

    def enable(**settings):
        calls.append(("enable", settings))
        if settings["variant"] == "L":
            raise RuntimeError("no L model")
        logic.session = SimpleNamespace(enabled=True)
        return logic.session

    def disable():
        if logic.session is not None:
            calls.append(("disable",))
        logic.session = None

    logic.enable, logic.disable = enable, disable
    logic.applyPreset = lambda node, name: calls.append(("preset", node, name))
    volume = object()
    parameters = volsr.VolSRParameterNode()  # outside Slicer a plain object holding the defaults
    parameters.inputVolume = None

    def applied():
        result = logic.apply(parameters)
        assert logic.parameters is parameters and result is logic.session
        done = list(calls)
        calls.clear()
        return done

    assert applied() == []
    parameters.inputVolume, parameters.preset = volume, "CT-AAA"
    assert applied() == [("preset", volume, "CT-AAA")]
    assert applied() == [], "written once"
    parameters.enabled = True
    shipped = {"volumeNode": volume, "scale": 2, "variant": "XS", "model": None, "device": "cpu"}
    assert applied() == [("enable", shipped)] and logic.enabled
    assert applied() == [], "unchanged: no restart"
    parameters.scale, parameters.modelPath = 8, " /models/s8.onnx "
    own = {**shipped, "scale": None, "model": "/models/s8.onnx"}  # a model file upscales by its own scale
    assert applied() == [("disable",), ("enable", own)]
    parameters.scale = 4
    assert applied() == [], "the scale is the model file's: no restart"
    parameters.preset = volsr.KEEP_PRESET
    assert applied() == []
    parameters.preset = "CT-AAA"
    assert applied() == [("preset", volume, "CT-AAA")], "chosen again: written again"
    logic.disable()  # e.g. switched off from the Python console
    calls.clear()
    assert applied() == [("enable", own)], "started again"

    parameters.variant = "L"
    with pytest.raises(RuntimeError, match="no L model"):
        logic.apply(parameters)
    assert parameters.enabled is False and not logic.enabled, "what could not start is unticked"
    calls.clear()
    assert applied() == []
    parameters.enabled, parameters.inputVolume = True, None
    with pytest.raises(ValueError, match="input volume"):
        logic.apply(parameters)
    assert parameters.enabled is False and calls == []
    parameters.inputVolume = volume
    assert applied() == [("preset", volume, "CT-AAA")], "a volume chosen again gets the preset"
    logic.cleanup()
    assert logic.parameters is None


# RAS <-> LPS ------------------------------------------------------------------------------------------
def write_ras_nrrd(path: Path, array: np.ndarray, ijk_to_ras: np.ndarray) -> Path:
    """A NRRD file in RAS space, the way Slicer writes a volume node (float32, raw, little endian)."""
    columns = " ".join("(" + ",".join(repr(float(v)) for v in ijk_to_ras[:3, c]) + ")" for c in range(3))
    nz, ny, nx = array.shape
    header = (f"NRRD0004\ntype: float\ndimension: 3\nspace: right-anterior-superior\nsizes: {nx} {ny} {nz}\n"
              f"space directions: {columns}\nkinds: domain domain domain\nendian: little\nencoding: raw\n"
              f"space origin: ({','.join(repr(float(v)) for v in ijk_to_ras[:3, 3])})\n\n")
    path.write_bytes(header.encode("ascii") + np.ascontiguousarray(array, dtype="<f4").tobytes())
    return path


def rotation_z(degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ijk_to_ras_matrix(directions: np.ndarray, spacing, origin) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = np.asarray(directions) @ np.diag(spacing)
    m[:3, 3] = origin
    return m


def test_points_and_cameras_change_sign_in_x_and_y():
    from volsr_core.hosts.slicer import (
        LPS_TO_RAS, RAS_TO_LPS, camera_lps_to_ras, camera_ras_to_lps, ijk_to_lps, lps_to_ras, ras_to_lps,
    )

    assert np.array_equal(ras_to_lps([10.0, 20.0, 30.0]), [-10.0, -20.0, 30.0])
    assert np.array_equal(lps_to_ras(ras_to_lps([[1.0, -2.0, 3.0], [4.0, 5.0, -6.0]])), [[1, -2, 3], [4, 5, -6]])
    assert np.array_equal(RAS_TO_LPS @ LPS_TO_RAS, np.eye(4)) and np.linalg.det(RAS_TO_LPS[:3, :3]) == 1.0
    m = np.eye(4)
    m[:3, 3] = (10.0, 20.0, 30.0)
    assert np.array_equal(ijk_to_lps(m)[:3, 3], [-10.0, -20.0, 30.0])

    # a camera anterior to the patient in RAS (y > 0) looking posterior, superior up ...
    ras = Camera(position=(10.0, 320.0, 30.0), focal_point=(10.0, 20.0, 30.0), view_up=(0.0, 0.0, 1.0),
                 view_angle=30.0, clipping_range=(100.0, 500.0))
    lps = camera_ras_to_lps(ras)
    # ... stands at LPS y < 0 (anterior), as Camera.framing's default anterior view does
    assert np.allclose(lps.position, (-10.0, -320.0, 30.0)) and np.allclose(lps.focal_point, (-10.0, -20.0, 30.0))
    assert np.allclose(lps.view_up, (0.0, 0.0, 1.0)) and lps.clipping_range == ras.clipping_range
    assert np.allclose(lps.direction_of_projection, (0.0, 1.0, 0.0))
    # the patient's left (RAS x < 0, LPS x > 0) is on the image's right in an anterior view
    left_lps = ras_to_lps([-50.0, 20.0, 30.0])
    assert lps.world_to_pixel(left_lps[None], 100, 100)[0, 0] > 50
    assert np.allclose(camera_lps_to_ras(lps).view_matrix(), ras.view_matrix())


@pytest.mark.parametrize("directions, spacing, origin", [
    (np.diag([-1.0, -1.0, 1.0]), (0.8, 0.9, 1.2), (40.0, 35.0, -20.0)),       # axial DICOM in Slicer: negative x/y
    (rotation_z(30.0) @ np.diag([-1.0, 1.0, 1.0]) @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]),
     (1.5, 0.7, 2.0), (-12.5, 60.0, 7.0)),  # oblique, axes permuted, left-handed
])
def test_an_ijk_to_ras_matrix_gives_the_geometry_our_reader_gives_for_the_same_file(tmp_path, directions, spacing,
                                                                                    origin):
    from volsr_core.hosts.slicer import ijk_to_ras_of, volume_from_ijk_to_ras

    array = make_phantom(shape=(6, 7, 8)).array
    ijk_to_ras = ijk_to_ras_matrix(directions, spacing, origin)
    read = Volume.load(write_ras_nrrd(tmp_path / "ras.nrrd", array, ijk_to_ras))  # SimpleITK: RAS file -> LPS
    ours = volume_from_ijk_to_ras(array, ijk_to_ras)
    assert np.array_equal(ours.array, read.array)
    assert np.allclose(ours.spacing, read.spacing) and np.allclose(ours.spacing, spacing)
    assert np.allclose(ours.origin, read.origin) and np.allclose(ours.direction, read.direction, atol=1e-6)
    assert np.allclose(ours.index_to_world, read.index_to_world, atol=1e-6)
    assert np.allclose(ijk_to_ras_of(ours), ijk_to_ras)
    if np.allclose(directions, np.diag([-1.0, -1.0, 1.0])):
        assert np.allclose(read.direction, np.eye(3)) and np.allclose(read.origin, (-40.0, -35.0, -20.0))


def test_slicer_volume_arrays_must_be_scalar():
    from volsr_core.hosts.slicer import volume_from_ijk_to_ras

    with pytest.raises(ValueError, match="scalar volumes"):
        volume_from_ijk_to_ras(np.zeros((4, 5, 6, 3), np.float32), np.eye(4))


# the VTK side (offscreen) ----------------------------------------------------------------------------------
def test_a_preset_is_written_into_an_existing_volume_property_in_place():
    pytest.importorskip("vtkmodules.vtkRenderingCore", reason="VTK is not installed (pip install 'volsr[vtk]')")
    from vtkmodules.vtkRenderingCore import vtkVolumeProperty

    from volsr_core.hosts.slicer import preset_for
    from volsr_core.scene.vtk_bridge import write_volume_property as apply_transfer_function
    from volsr_core.scene import get_preset
    from volsr_core.scene.vtk_bridge import from_vtk_volume_property

    prop = vtkVolumeProperty()
    prop.GetRGBTransferFunction(0).AddRGBPoint(0.0, 1.0, 0.0, 0.0)  # what Slicer's property node starts with
    color, opacity = prop.GetRGBTransferFunction(0), prop.GetScalarOpacity(0)
    before = prop.GetMTime()
    volume = Volume.from_record(make_phantom(shape=(20, 20, 20)))  # HU: CT presets stay as designed
    for name in ("CT-AAA", "MR-Default"):
        tf = preset_for(name, volume)
        apply_transfer_function(prop, tf)
        back = from_vtk_volume_property(prop)
        assert np.allclose(back.color, tf.color) and np.allclose(back.scalar_opacity, tf.scalar_opacity)
        assert (back.gradient_opacity is None) == (tf.gradient_opacity is None)
        assert back.shade == tf.shade and back.specular_power == pytest.approx(tf.specular_power)
        assert prop.GetRGBTransferFunction(0) is color and prop.GetScalarOpacity(0) is opacity
        assert prop.GetMTime() > before
    assert np.allclose(preset_for("CT-AAA", volume).scalar_opacity, get_preset("CT-AAA").scalar_opacity)
    mr = Volume(array=np.linspace(0, 400, 8000, dtype=np.float32).reshape(20, 20, 20))  # no HU: placed on it
    assert preset_for("CT-AAA", mr).scalar_opacity[:, 0].max() <= 400.0 + 1e-3


def test_find_vtk_volume_takes_the_first_visible_one():
    pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")
    from vtkmodules.vtkRenderingCore import vtkRenderer, vtkVolume
    from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper

    from volsr_core.hosts.slicer import find_vtk_volume

    renderer = vtkRenderer()
    with pytest.raises(ValueError, match="no visible volume"):
        find_vtk_volume(renderer)
    hidden, shown = vtkVolume(), vtkVolume()
    for v in (hidden, shown):
        v.SetMapper(vtkOpenGLGPUVolumeRayCastMapper())
        renderer.AddVolume(v)
    hidden.VisibilityOff()
    assert find_vtk_volume(renderer) is shown


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 or [0, 1] images (capped at 100 dB for identical ones)."""
    a, b = (np.asarray(x, dtype=np.float64) / (255.0 if x.dtype == np.uint8 else 1.0) for x in (a, b))
    return float(10 * np.log10(1.0 / max(np.mean((a - b) ** 2), 1e-10)))


class RasScene:
    """What Slicer's 3D view holds: a vtkImageData with origin 0 and spacing 1 (a volume node's image),
    the node's IJK-to-RAS matrix as the vtkVolume's user matrix, a GPU ray-cast mapper, and a
    vtkCamera in RAS; offscreen (EGL)."""

    def __init__(self, array: np.ndarray, ijk_to_ras: np.ndarray):
        from vtkmodules.util.numpy_support import numpy_to_vtk
        from vtkmodules.vtkCommonDataModel import vtkImageData
        from vtkmodules.vtkCommonMath import vtkMatrix4x4
        from vtkmodules.vtkRenderingCore import vtkRenderer, vtkRenderWindow, vtkVolume, vtkVolumeProperty
        from vtkmodules.vtkRenderingVolumeOpenGL2 import vtkOpenGLGPUVolumeRayCastMapper

        image = vtkImageData()
        image.SetDimensions(array.shape[2], array.shape[1], array.shape[0])
        scalars = numpy_to_vtk(np.ascontiguousarray(array, dtype=np.float32).ravel(), deep=True)
        image.GetPointData().SetScalars(scalars)
        matrix = vtkMatrix4x4()
        for r in range(4):
            for c in range(4):
                matrix.SetElement(r, c, float(ijk_to_ras[r, c]))
        self.mapper = vtkOpenGLGPUVolumeRayCastMapper()
        self.mapper.SetInputData(image)
        self.volume = vtkVolume()
        self.volume.SetMapper(self.mapper)
        self.volume.SetUserMatrix(matrix)
        self.volume.SetProperty(vtkVolumeProperty())
        self.renderer = vtkRenderer()
        self.renderer.SetLayer(0)
        self.renderer.AddVolume(self.volume)
        self.window = vtkRenderWindow()
        self.window.SetOffScreenRendering(True)
        self.window.SetSize(W, H)
        self.window.AddRenderer(self.renderer)

    def close(self):
        self.window.Finalize()


def test_volsr_draws_a_ras_scene_as_the_pipeline_draws_it_in_lps(tmp_path, model):
    """The RAS scene through SlicerSession equals our Pipeline on the file our reader reads, seen by the
    camera converted by hand; then the history is used, the frame time is read and VolSR goes off."""
    pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")
    from volsr_core.hosts.slicer import SlicerSession, session_for
    from volsr_core.images import to_uint8
    from volsr_core.scene.vtk_bridge import camera_from_vtk, read_window
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene.vtk_bridge import from_vtk_volume_property

    array = make_phantom(shape=(40, 44, 36)).array
    ijk_to_ras = ijk_to_ras_matrix(np.diag([-1.0, -1.0, 1.0]), (1.6, 1.4, 1.5), (28.0, 30.0, -29.0))
    reader_volume = Volume.load(write_ras_nrrd(tmp_path / "phantom.nrrd", array, ijk_to_ras))
    scene = RasScene(array, ijk_to_ras)
    center_ras = (ijk_to_ras @ np.array([35 / 2, 43 / 2, 39 / 2, 1.0]))[:3]
    vtk_camera = scene.renderer.GetActiveCamera()  # Slicer's default: anterior (RAS +y), superior up
    vtk_camera.SetFocalPoint(*center_ras)
    vtk_camera.SetPosition(*(center_ras + (0.0, 190.0, 0.0)))
    vtk_camera.SetViewUp(0.0, 0.0, 1.0)
    vtk_camera.SetViewAngle(30.0)
    vtk_camera.SetClippingRange(100.0, 300.0)

    session = session_for(scene.renderer, scene.volume, array, ijk_to_ras, model, preset="CT-Phantom")
    adapter = session.adapter
    assert adapter.overlay.GetLayer() == 3 and scene.window.GetNumberOfLayers() >= 4
    assert np.allclose(adapter.pipeline.caster.volume.index_to_world, reader_volume.index_to_world)
    tf = from_vtk_volume_property(scene.volume.GetProperty())
    reference = Pipeline(reader_volume, tf, model, scale=4, size=(W, H))
    # the LPS camera by hand: x and y of position and focal point negated, up unchanged
    lps_camera = Camera(position=(-center_ras[0], -center_ras[1] - 190.0, center_ras[2]),
                        focal_point=(-center_ras[0], -center_ras[1], center_ras[2]), view_up=(0.0, 0.0, 1.0),
                        view_angle=30.0, clipping_range=(100.0, 300.0))
    assert session.status_text() == "waiting for the first frame" and session.frame_time_ms is None

    scene.window.Render()
    first = read_window(scene.window)
    expected = reference.render(lps_camera)
    assert adapter.last_error == "" and adapter.frames == 1
    assert np.allclose(adapter.last_camera.view_matrix(), lps_camera.view_matrix())
    assert first.std() > 5, "the window shows an image, not a blank frame"
    own, lps = psnr(first, to_uint8(adapter.last_image)), psnr(first, expected)
    print(f"frame 1: window vs adapter {own:.1f} dB, vs the LPS pipeline {lps:.1f} dB")
    assert own >= 40 and lps >= 40
    assert session.frame_time_ms > 0 and "ms/frame" in session.status_text()

    vtk_camera.Azimuth(5)
    scene.window.Render()
    second = read_window(scene.window)
    ras_camera, flip = camera_from_vtk(vtk_camera, W / H), np.array([-1.0, -1.0, 1.0])
    expected = reference.render(dataclasses.replace(ras_camera, position=ras_camera.position * flip,
                                                    focal_point=ras_camera.focal_point * flip,
                                                    view_up=ras_camera.view_up * flip))
    following = psnr(second, expected)
    print(f"frame 2 (azimuth 5): vs the LPS pipeline with history {following:.1f} dB")
    assert following >= 40 and psnr(second, first) < 35
    assert adapter.pipeline.upscaler.resets == 0 and adapter.resets == 0, "the history was used"

    session.enabled = False
    scene.window.Render()
    assert not scene.window.GetRenderers().IsItemPresent(adapter.overlay) and scene.volume.GetVisibility() == 1
    assert session.status_text() == "off" and adapter.frames == 2

    # the volume read from VTK (no Volume given) lands in the same LPS place
    other = SlicerSession(scene.renderer, scene.volume, None, model, scale=4, enabled=False)
    assert np.allclose(other.adapter.pipeline.caster.volume.index_to_world, reader_volume.index_to_world)
    assert np.array_equal(other.adapter.pipeline.caster.volume.array, reader_volume.array)
    other.detach()
    session.detach()
    scene.close()


def test_a_changed_volume_node_replaces_the_volume_and_restarts_the_history(model):
    pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")
    from volsr_core.hosts.slicer import session_for, volume_from_ijk_to_ras

    array = make_phantom(shape=(24, 24, 24)).array
    ijk_to_ras = ijk_to_ras_matrix(np.diag([-1.0, -1.0, 1.0]), (2.0, 2.0, 2.0), (23.0, 23.0, -23.0))
    scene = RasScene(array, ijk_to_ras)
    scene.renderer.ResetCamera()
    session = session_for(scene.renderer, scene.volume, array, ijk_to_ras, model, preset="CT-Phantom")
    scene.window.Render()
    moved = ijk_to_ras.copy()
    moved[:3, 3] += (5.0, 0.0, 0.0)  # the node was moved 5 mm to the patient's right (RAS x)
    session.set_volume(volume_from_ijk_to_ras(array[::-1].copy(), moved))
    assert session.adapter.last_reset_reason == "new volume"
    assert np.allclose(session.adapter.pipeline.caster.volume.origin, (-28.0, -23.0, -23.0))
    scene.window.Render()
    assert session.last_error == "" and session.adapter.frames == 2
    assert np.array_equal(session.adapter.pipeline.caster.volume.array, array[::-1]), "kept, not re-read from VTK"
    session.detach()
    scene.close()


def test_session_checks_scale_and_variant(model):
    pytest.importorskip("vtkmodules.vtkRenderingVolumeOpenGL2", reason="VTK is not installed (pip install 'volsr[vtk]')")
    from volsr_core.hosts.slicer import SlicerSession

    scene = RasScene(np.zeros((4, 4, 4), np.float32), np.eye(4))
    with pytest.raises(ValueError, match="scale"):
        SlicerSession(scene.renderer, scene.volume, None, model, scale=3)
    with pytest.raises(ValueError, match="variant"):
        SlicerSession(scene.renderer, scene.volume, None, model, variant="XL")
    scene.close()


def test_the_onnx_engine_runs_without_torch(model):
    """Slicer's requirements.txt installs onnxruntime, not torch."""
    code = ("import sys; sys.modules['torch'] = None\n"
            "from volsr_core.runtime.engines import OnnxEngine\n"
            f"OnnxEngine({str(model)!r})\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr.strip().splitlines()[-1]
