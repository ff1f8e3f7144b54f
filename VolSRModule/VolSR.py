"""VolSR: learned super-resolution of the volume in 3D Slicer's 3D view (scripted module).

Slicer's template: ``VolSR`` (module), ``VolSRWidget`` (GUI, Resources/UI/VolSR.ui), ``VolSRLogic``
(works without the GUI), ``VolSRTest`` (self-test, run by "Reload and Test" or ctest).

The work is done by ``volsr_core.hosts.slicer`` (no Slicer in it, tested outside Slicer): the VTK
adapter draws the 3D view's vtkVolume at 1/scale of the view and upscales it, in an overlay
renderer on layer 3; Slicer's RAS world is converted to VolSR's LPS (x and y change sign) for the
volume (IJK-to-RAS) and the camera. ``volsr_core`` is imported from an installed ``volsr`` or from
the source checkout this folder belongs to; its Python dependencies (Resources/requirements.txt)
are installed at first use. See docs/slicer.md.

Outside Slicer this file still imports (the Slicer classes get stand-in bases and are unusable);
``slicer``, ``qt`` and ``ctk`` are used only inside the Slicer-only classes.
"""
from __future__ import annotations

import importlib
import importlib.util
import logging
import os
import re
import sys
import unittest
from pathlib import Path

try:
    import slicer
    from slicer.ScriptedLoadableModule import (
        ScriptedLoadableModule, ScriptedLoadableModuleLogic, ScriptedLoadableModuleTest, ScriptedLoadableModuleWidget,
    )
except ImportError:  # outside 3D Slicer: only the plain helpers below are usable
    slicer = None

    class ScriptedLoadableModule:  # noqa: D101  (stand-in base outside Slicer)
        def __init__(self, parent=None):
            self.parent = parent

    class ScriptedLoadableModuleWidget:  # noqa: D101
        def __init__(self, parent=None):
            self.parent = parent

    class ScriptedLoadableModuleLogic:  # noqa: D101
        def __init__(self, parent=None):
            self.parent = parent

    ScriptedLoadableModuleTest = unittest.TestCase


MODULE_DIR = Path(__file__).resolve().parent
REQUIREMENTS = MODULE_DIR / "Resources" / "requirements.txt"
KEEP_PRESET = "Slicer's own"
# shown before volsr_core can be imported (its dependencies are installed when VolSR is first switched on)
FALLBACK_PRESETS = ("CT-AAA", "CT-Bone", "CT-Cardiac", "CT-Chest-Contrast-Enhanced", "CT-Lung", "CT-Phantom",
                    "CT-Soft-Tissue", "MR-Angio", "MR-Default")


# plain helpers (no Slicer) -----------------------------------------------------------------------
def requirementLines(path: Path = REQUIREMENTS) -> list[str]:
    """The requirement specifiers of Resources/requirements.txt (comments and blank lines dropped)."""
    lines = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            lines.append(line)
    return lines


def requirementName(spec: str) -> str:
    """The distribution name of a specifier, normalised ("PyYAML>=6" -> "pyyaml")."""
    name = re.split(r"[\s<>=!~;\[]", spec, maxsplit=1)[0]
    return re.sub(r"[-_.]+", "-", name).lower()


def missingRequirements(specs: list[str]) -> list[str]:
    """The specifiers whose distribution is not installed at all (versions are pip's business)."""
    from importlib import metadata

    missing = []
    for spec in specs:
        try:
            metadata.version(requirementName(spec))
        except metadata.PackageNotFoundError:
            missing.append(spec)
    return missing


def sourceCheckout(moduleFile: str | os.PathLike = __file__) -> Path | None:
    """The VolSR source checkout this module folder lies in (``Path(moduleFile).parents[1]``), if any."""
    root = Path(moduleFile).resolve().parents[1]
    return root if (root / "volsr_core" / "__init__.py").is_file() else None


def importVolsrCore(moduleFile: str | os.PathLike = __file__):
    """``volsr_core``: installed (pip), else from the source checkout next to this module.

    From a checkout the repository root goes on ``sys.path``, and ``volsr_core.resources`` (which
    setup.py maps to the checkout's ``resources/``: presets, models) is registered from there.
    """
    try:
        return importlib.import_module("volsr_core")
    except ImportError:
        root = sourceCheckout(moduleFile)
        if root is None:
            raise ImportError("volsr_core is neither installed (pip install volsr) nor in a source checkout around "
                              f"{Path(moduleFile).resolve().parent}") from None
        if str(root) not in sys.path:
            sys.path.insert(0, str(root))
        importlib.invalidate_caches()
        core = importlib.import_module("volsr_core")
    if "volsr_core.resources" not in sys.modules:
        try:
            importlib.import_module("volsr_core.resources")
        except ImportError:
            resources = Path(core.__file__).resolve().parents[1] / "resources"
            if not (resources / "__init__.py").is_file():
                raise ImportError(f"volsr_core's resources are missing ({resources})") from None
            spec = importlib.util.spec_from_file_location("volsr_core.resources", resources / "__init__.py",
                                                          submodule_search_locations=[str(resources)])
            module = importlib.util.module_from_spec(spec)
            sys.modules["volsr_core.resources"] = module
            spec.loader.exec_module(module)
            core.resources = module
    return core


def presetNames() -> list[str]:
    """VolSR's preset names (the fixed list while volsr_core cannot be imported yet)."""
    try:
        importVolsrCore()
        from volsr_core.scene.presets import list_presets

        return list(list_presets())
    except Exception:  # dependencies not installed yet
        return list(FALLBACK_PRESETS)


#
# VolSR
#
class VolSR(ScriptedLoadableModule):
    """The module's description for Slicer's module list."""

    def __init__(self, parent):
        ScriptedLoadableModule.__init__(self, parent)
        self.parent.title = "VolSR"
        self.parent.categories = ["Rendering"]
        self.parent.dependencies = ["VolumeRendering"]
        self.parent.contributors = ["VolSR developers"]
        self.parent.helpText = (
            "Learned super-resolution of direct volume rendering: the first 3D view's volume is ray cast at "
            "1/2, 1/4 or 1/8 of the view's resolution and upscaled by a network that reuses previous frames. "
            "Pick a volume, a scale and a model variant, and switch VolSR on. See docs/slicer.md in the VolSR "
            "repository.")
        self.parent.acknowledgementText = (
            "After Devkota and Pattanaik, Deep Learning based Super-Resolution for Medical Volume Visualization "
            "with Direct Volume Rendering.")


#
# VolSRWidget
#
class VolSRWidget(ScriptedLoadableModuleWidget):
    """GUI: input volume, preset, scale, variant, on/off and the frame time of the last VolSR frame."""

    def __init__(self, parent=None):
        ScriptedLoadableModuleWidget.__init__(self, parent)
        self.logic = None
        self.ui = None
        self._timer = None
        self._sceneObservers = []
        self._updating = False

    def setup(self):
        import ctk
        import qt

        ScriptedLoadableModuleWidget.setup(self)
        uiWidget = slicer.util.loadUI(self.resourcePath("UI/VolSR.ui"))
        self.layout.addWidget(uiWidget)
        self.ui = slicer.util.childWidgetVariables(uiWidget)
        uiWidget.setMRMLScene(slicer.mrmlScene)
        self.logic = VolSRLogic()

        self.ui.presetComboBox.addItem(KEEP_PRESET)
        for name in presetNames():
            self.ui.presetComboBox.addItem(name)
        self.ui.modelPathLineEdit.filters = ctk.ctkPathLineEdit.Files
        self.ui.modelPathLineEdit.nameFilters = ["VolSR models (*.onnx *.pt)"]

        self.ui.enableCheckBox.connect("toggled(bool)", self.onEnableToggled)
        self.ui.inputSelector.connect("currentNodeChanged(vtkMRMLNode*)", self.onSettingsChanged)
        self.ui.presetComboBox.connect("currentIndexChanged(int)", self.onPresetChanged)
        for combo in (self.ui.scaleComboBox, self.ui.variantComboBox, self.ui.deviceComboBox):
            combo.connect("currentIndexChanged(int)", self.onSettingsChanged)
        self.ui.modelPathLineEdit.connect("currentPathChanged(QString)", self.onSettingsChanged)

        self._timer = qt.QTimer()
        self._timer.setInterval(500)
        self._timer.connect("timeout()", self.updateFrameTime)
        self._sceneObservers = [
            slicer.mrmlScene.AddObserver(slicer.mrmlScene.StartCloseEvent, self.onSceneStartClose)]
        self.updateFrameTime()

    def cleanup(self):
        if self._timer is not None:
            self._timer.stop()
        for tag in self._sceneObservers:
            slicer.mrmlScene.RemoveObserver(tag)
        self._sceneObservers = []
        if self.logic is not None:
            self.logic.cleanup()

    def enter(self):
        if self._timer is not None:
            self._timer.start()
        self.updateFrameTime()

    def exit(self):
        if self._timer is not None:
            self._timer.stop()

    # settings --------------------------------------------------------------------------------------
    def settings(self) -> dict:
        path = self.ui.modelPathLineEdit.currentPath.strip()
        preset = self.ui.presetComboBox.currentText
        return {"scale": int(self.ui.scaleComboBox.currentText), "variant": self.ui.variantComboBox.currentText,
                "model": path or None, "device": self.ui.deviceComboBox.currentText,
                "preset": None if preset == KEEP_PRESET else preset}

    def setChecked(self, on: bool):
        self._updating = True
        try:
            self.ui.enableCheckBox.checked = on
        finally:
            self._updating = False

    def start(self) -> bool:
        import qt

        node = self.ui.inputSelector.currentNode()
        if node is None:
            self.ui.statusLabel.text = "Choose an input volume first."
            return False
        try:
            slicer.app.setOverrideCursor(qt.Qt.WaitCursor)
            try:
                self.logic.enable(node, **self.settings())
            finally:
                slicer.app.restoreOverrideCursor()
        except Exception as err:
            logging.exception("VolSR could not start")
            self.ui.statusLabel.text = f"Not started: {err}"
            slicer.util.errorDisplay(f"VolSR could not start: {err}")
            return False
        self.ui.statusLabel.text = ""
        if self._timer is not None:
            self._timer.start()
        return True

    # slots -------------------------------------------------------------------------------------------
    def onEnableToggled(self, on):
        if self._updating:
            return
        if on:
            if not self.start():
                self.setChecked(False)
        else:
            self.logic.disable()
        self.updateFrameTime()

    def onSettingsChanged(self, *args):
        if self._updating or not self.logic.enabled:
            return
        if not self.start():
            self.logic.disable()
            self.setChecked(False)
        self.updateFrameTime()

    def onPresetChanged(self, index):
        node = self.ui.inputSelector.currentNode()
        name = self.ui.presetComboBox.currentText
        if self._updating or node is None or name == KEEP_PRESET:
            return
        try:
            self.logic.applyPreset(node, name)
        except Exception as err:
            self.ui.statusLabel.text = f"Preset not applied: {err}"

    def onSceneStartClose(self, caller, event):
        self.logic.disable()
        self.setChecked(False)

    def updateFrameTime(self):
        if self.ui is not None and self.logic is not None:
            self.ui.frameTimeLabel.text = self.logic.statusText()


#
# VolSRLogic
#
class VolSRLogic(ScriptedLoadableModuleLogic):
    """Switches VolSR on and off for a volume node in a 3D view; no GUI needed.

    ``enable(volumeNode, scale=4, variant="S")`` shows the node with volume rendering (if it was
    not), attaches VolSR to the 3D view's first renderer and returns the
    ``volsr_core.hosts.slicer.SlicerSession``; ``disable()`` gives the view back to Slicer.
    """

    def __init__(self, parent=None):
        ScriptedLoadableModuleLogic.__init__(self, parent)
        self.session = None
        self.volumeNode = None
        self.viewIndex = 0
        self._nodeObservations = []
        self._dependenciesChecked = False

    # dependencies ------------------------------------------------------------------------------------
    def ensureDependencies(self) -> None:
        """Install what Resources/requirements.txt lists and is missing (asking first), then import volsr_core."""
        if self._dependenciesChecked:
            return
        if sys.version_info < (3, 10):
            raise RuntimeError("VolSR needs Python 3.10 or newer (Slicer 5.8 or later); this Slicer has Python "
                               f"{sys.version_info.major}.{sys.version_info.minor}")
        specs = requirementLines()
        try:
            import slicer.packaging as packaging

            ensure = packaging.pip_ensure
        except (ImportError, AttributeError):  # Slicer before slicer.packaging (5.9)
            ensure = None
        if ensure is not None:
            ensure(packaging.load_requirements(str(REQUIREMENTS)), requester="VolSR")
        else:
            missing = missingRequirements(specs)
            if missing and (slicer.app.testingEnabled() or slicer.util.confirmOkCancelDisplay(
                    "VolSR needs these Python packages, which will be installed now:\n" + "\n".join(missing),
                    windowTitle="VolSR")):
                for spec in missing:  # one at a time: older pip_install splits its argument at spaces
                    slicer.util.pip_install(spec)
        missing = missingRequirements(specs)
        if missing:
            raise RuntimeError("missing Python packages: " + ", ".join(missing)
                               + f" (install them with slicer.util.pip_install, see {REQUIREMENTS})")
        importVolsrCore()
        self._dependenciesChecked = True

    # the 3D view -------------------------------------------------------------------------------------
    def threeDView(self, viewIndex: int | None = None):
        index = self.viewIndex if viewIndex is None else viewIndex
        widget = slicer.app.layoutManager().threeDWidget(index)
        if widget is None:
            raise RuntimeError(f"there is no 3D view {index} in the current layout")
        return widget.threeDView()

    def threeDRenderer(self, viewIndex: int | None = None):
        """The 3D view's first renderer (the one that draws volumes)."""
        return self.threeDView(viewIndex).renderWindow().GetRenderers().GetItemAsObject(0)

    def displayNode(self, volumeNode, create: bool = True):
        """The node's volume rendering display node, created (and shown) when it has none."""
        vrLogic = slicer.modules.volumerendering.logic()
        displayNode = vrLogic.GetFirstVolumeRenderingDisplayNode(volumeNode)
        if displayNode is None and create:
            displayNode = vrLogic.CreateDefaultVolumeRenderingNodes(volumeNode)
        if displayNode is not None and create:
            displayNode.SetVisibility(True)
        return displayNode

    def vtkVolumeFor(self, volumeNode, viewIndex: int | None = None):
        """The vtkVolume that draws ``volumeNode`` in the 3D view."""
        from volsr_core.hosts.slicer import find_vtk_volume

        view = self.threeDView(viewIndex)
        view.forceRender()  # the displayable manager builds its pipeline on the first render
        try:
            manager = view.displayableManagerByClassName("vtkMRMLVolumeRenderingDisplayableManager")
            actor = manager.GetVolumeActor(volumeNode) if manager is not None else None
        except AttributeError:  # an older Slicer without these accessors
            actor = None
        if actor is not None and not actor.IsA("vtkMultiVolume"):
            return actor
        return find_vtk_volume(self.threeDRenderer(viewIndex))

    # the volume --------------------------------------------------------------------------------------
    def ijkToWorld(self, volumeNode):
        """4x4 IJK-to-world (RAS) of the node: its IJK-to-RAS after its parent transform (linear only)."""
        import numpy as np
        import vtk

        from volsr_core.scene.vtk_bridge import matrix_4x4

        ijkToRas = vtk.vtkMatrix4x4()
        volumeNode.GetIJKToRASMatrix(ijkToRas)
        m = matrix_4x4(ijkToRas)
        parent = volumeNode.GetParentTransformNode()
        if parent is not None:
            if not parent.IsTransformToWorldLinear():
                raise ValueError("VolSR draws volumes under linear transforms only (harden the transform first)")
            toWorld = vtk.vtkMatrix4x4()
            parent.GetMatrixTransformToWorld(toWorld)
            m = matrix_4x4(toWorld) @ m
        return np.asarray(m)

    def volumeFromNode(self, volumeNode):
        """Our Volume (LPS) from the node's voxels (``arrayFromVolume``: (k, j, i)) and IJK-to-world."""
        from volsr_core.hosts.slicer import volume_from_ijk_to_ras

        array = slicer.util.arrayFromVolume(volumeNode)
        return volume_from_ijk_to_ras(array, self.ijkToWorld(volumeNode), source=volumeNode.GetName())

    def applyPreset(self, volumeNode, name: str) -> None:
        """Write VolSR's preset ``name``, placed on the node's values, into its volume property node."""
        self.ensureDependencies()
        from volsr_core.hosts.slicer import preset_for
        from volsr_core.scene.vtk_bridge import write_volume_property as apply_transfer_function

        displayNode = self.displayNode(volumeNode)
        propertyNode = displayNode.GetVolumePropertyNode()
        apply_transfer_function(propertyNode.GetVolumeProperty(), preset_for(name, self.volumeFromNode(volumeNode)))
        propertyNode.Modified()
        self.render()

    # on / off ----------------------------------------------------------------------------------------
    def enable(self, volumeNode, scale: int = 4, variant: str = "S", model=None, preset: str | None = None,
               device: str = "cpu", viewIndex: int | None = None):
        """Draw ``volumeNode`` with VolSR in the 3D view; returns the SlicerSession."""
        self.ensureDependencies()
        from volsr_core.hosts.slicer import SlicerSession

        self.disable()
        if viewIndex is not None:
            self.viewIndex = viewIndex
        displayNode = self.displayNode(volumeNode)
        if preset:
            self.applyPreset(volumeNode, preset)
        vtkVolume = self.vtkVolumeFor(volumeNode)
        propertyNode = displayNode.GetVolumePropertyNode()
        if propertyNode is not None and not _sameVtkObject(vtkVolume.GetProperty(), propertyNode.GetVolumeProperty()):
            logging.warning("VolSR: the 3D view's vtkVolume does not use the volume property node's property")
        self.session = SlicerSession(self.threeDRenderer(), vtkVolume, self.volumeFromNode(volumeNode), model,
                                     scale=scale, variant=variant, device=device)
        self.volumeNode = volumeNode
        self._observeNode(volumeNode)
        self.render()
        return self.session

    def disable(self) -> None:
        """Slicer draws the 3D view itself again."""
        self._unobserveNode()
        if self.session is not None:
            self.session.detach()
            self.session = None
            self.render()
        self.volumeNode = None

    @property
    def enabled(self) -> bool:
        return self.session is not None and self.session.enabled

    def render(self) -> None:
        try:
            self.threeDView().scheduleRender()
        except RuntimeError:
            pass

    def frameTimeMs(self):
        """ms VolSR spent on the last frame, None when off or before the first frame."""
        return None if self.session is None else self.session.frame_time_ms

    def statusText(self) -> str:
        return "off" if self.session is None else self.session.status_text()

    def cleanup(self) -> None:
        self.disable()

    # following the node ------------------------------------------------------------------------------
    def _observeNode(self, node) -> None:
        for event in (slicer.vtkMRMLVolumeNode.ImageDataModifiedEvent,
                      slicer.vtkMRMLTransformableNode.TransformModifiedEvent):
            self._nodeObservations.append((node, node.AddObserver(event, self._onNodeChanged)))

    def _unobserveNode(self) -> None:
        for node, tag in self._nodeObservations:
            node.RemoveObserver(tag)
        self._nodeObservations = []

    def _onNodeChanged(self, caller, event) -> None:
        if self.session is None or self.volumeNode is None:
            return
        try:
            self.session.set_volume(self.volumeFromNode(self.volumeNode))
        except Exception as err:  # e.g. a non-linear transform: Slicer draws it
            logging.error(f"VolSR: {err}; switched off")
            self.disable()
        self.render()


def _sameVtkObject(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a is b or a.GetAddressAsString("vtkObject") == b.GetAddressAsString("vtkObject")


#
# VolSRTest
#
class VolSRTest(ScriptedLoadableModuleTest):
    """Self-test inside Slicer: VolSR draws a volume in the 3D view and gives it back."""

    def setUp(self):
        slicer.mrmlScene.Clear()

    def runTest(self):
        self.setUp()
        self.test_ras_to_lps()
        self.setUp()
        self.test_VolSR_draws_the_3D_view()

    # helpers -----------------------------------------------------------------------------------------
    def phantomVolumeNode(self, shape=(64, 64, 64)):
        """A scalar volume node holding VolSR's CT phantom, placed as our reader places it (LPS -> RAS)."""
        import vtk

        importVolsrCore()
        from volsr_core.hosts.slicer import ijk_to_ras_of
        from volsr_core.io import make_phantom
        from volsr_core.scene import Volume

        volume = Volume.from_record(make_phantom(shape=shape))
        node = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLScalarVolumeNode", "VolSRPhantom")
        slicer.util.updateVolumeFromArray(node, volume.array)
        matrix = vtk.vtkMatrix4x4()
        for r, row in enumerate(ijk_to_ras_of(volume)):
            for c, value in enumerate(row):
                matrix.SetElement(r, c, float(value))
        node.SetIJKToRASMatrix(matrix)
        node.CreateDefaultDisplayNodes()
        return node

    def testModel(self):
        """The shipped S 4x model (None), else an untrained one exported here (needs PyTorch)."""
        from volsr_core.errors import InputError
        from volsr_core.runtime.models import model_file

        try:
            model_file("S", 4)
            return None
        except InputError:
            pass
        try:
            import torch

            from volsr_core.runtime.export import export_onnx
            from volsr_core.sr.network import SuperResolutionNet, variant_config
        except ImportError:
            self.skipTest("no shipped S 4x model and no PyTorch to export an untrained one")
        torch.manual_seed(0)
        net = SuperResolutionNet(variant_config("S", 4, 0, taau_base=True)).eval()
        return str(export_onnx(net, Path(slicer.app.temporaryPath) / "VolSRTest-S4.onnx"))

    # tests -------------------------------------------------------------------------------------------
    def test_ras_to_lps(self):
        self.delayDisplay("RAS -> LPS")
        importVolsrCore()
        import numpy as np

        from volsr_core.hosts.slicer import ras_to_lps, volume_from_ijk_to_ras

        self.assertTrue(np.allclose(ras_to_lps([10.0, 20.0, 30.0]), [-10.0, -20.0, 30.0]))
        ijkToRas = np.array([[-0.8, 0, 0, 40.0], [0, -0.9, 0, 35.0], [0, 0, 1.2, -20.0], [0, 0, 0, 1]])
        volume = volume_from_ijk_to_ras(np.zeros((3, 4, 5), np.float32), ijkToRas)
        self.assertTrue(np.allclose(volume.direction, np.eye(3)))
        self.assertTrue(np.allclose(volume.origin, (-40.0, -35.0, -20.0)))
        self.assertTrue(np.allclose(volume.spacing, (0.8, 0.9, 1.2)))

    def test_VolSR_draws_the_3D_view(self):
        self.delayDisplay("VolSR in the 3D view")
        logic = VolSRLogic()
        logic.ensureDependencies()
        from volsr_core.scene.vtk_bridge import read_window

        node = self.phantomVolumeNode()
        model = self.testModel()
        slicer.app.layoutManager().setLayout(slicer.vtkMRMLLayoutNode.SlicerLayoutOneUp3DView)
        slicer.app.processEvents()
        session = logic.enable(node, scale=4, variant="S", model=model, preset="CT-Phantom")
        view = logic.threeDView()
        session.renderer.ResetCamera()
        for _ in range(2):  # two frames: the second one uses the first as history
            view.forceRender()
            slicer.app.processEvents()
        self.assertEqual(session.last_error, "")
        self.assertGreaterEqual(session.adapter.frames, 2)
        self.assertGreater(session.frame_time_ms or 0.0, 0.0)
        self.assertGreater(float(session.adapter.last_image.std()), 0.01, "VolSR's image is blank")
        pixels = read_window(view.renderWindow(), session.renderer)
        self.assertGreater(float(pixels.std()), 1.0, "the 3D view shows a blank image")
        self.delayDisplay(f"VolSR on: {logic.statusText()}")

        vtkVolume, overlay = session.vtk_volume, session.adapter.overlay
        logic.disable()
        view.forceRender()
        self.assertFalse(view.renderWindow().GetRenderers().IsItemPresent(overlay))
        self.assertEqual(vtkVolume.GetVisibility(), 1)
        self.assertEqual(logic.statusText(), "off")
        logic.cleanup()
        self.delayDisplay("Test passed")
