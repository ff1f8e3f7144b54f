"""VolSR: learned super-resolution of the volume in 3D Slicer's 3D view (scripted module).

Slicer's template: ``VolSRParameterNode`` (the module's settings, kept in the scene's parameter node
and saved with the scene), ``VolSR`` (module), ``VolSRWidget`` (GUI, Resources/UI/VolSR.ui, bound to
the parameter node), ``VolSRLogic`` (works from a parameter node, or from plain arguments, without
the GUI), ``VolSRTest`` (self-test, run by "Reload and Test" or ctest).

The work is done by ``volsr_core.hosts.slicer`` (no Slicer in it, tested outside Slicer): the VTK
adapter draws the 3D view's vtkVolume at 1/scale of the view and upscales it, in an overlay
renderer on layer 3; Slicer's RAS world is converted to VolSR's LPS (x and y change sign) for the
volume (IJK-to-RAS) and the camera. ``VolSRLib.bootstrap`` installs VolSR's Python dependencies
(Resources/requirements.txt) at first use and imports ``volsr_core`` from an installed ``volsr`` or
from the source checkout this folder belongs to. See docs/slicer.md.

Outside Slicer this file still imports (the Slicer names get stand-ins and the classes are
unusable), with this folder on ``sys.path`` as Slicer puts it there; ``slicer``, ``qt``, ``ctk`` and
``vtk`` are used only inside the Slicer-only classes. No ``from __future__ import annotations``:
``slicer.parameterNodeWrapper`` reads the parameter node's annotations as objects.
"""
import logging
import sys
import unittest
from pathlib import Path
from typing import Annotated

if sys.version_info < (3, 10):  # volsr_core and the annotations below (X | None) need it
    raise ImportError("VolSR needs Python 3.10 or newer (Slicer 5.8 or later); this Slicer has Python "
                      f"{sys.version_info.major}.{sys.version_info.minor}")

from VolSRLib import bootstrap  # after the version check

try:
    import slicer
except ImportError:  # outside 3D Slicer
    slicer = None

if slicer is not None:
    import vtk
    from slicer import vtkMRMLScalarVolumeNode
    from slicer.parameterNodeWrapper import Choice, parameterNodeWrapper
    from slicer.ScriptedLoadableModule import (
        ScriptedLoadableModule, ScriptedLoadableModuleLogic, ScriptedLoadableModuleTest, ScriptedLoadableModuleWidget,
    )
    from slicer.util import VTKObservationMixin
else:  # stand-ins, so that the classes below can be defined and inspected
    vtk = None

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

    class VTKObservationMixin:  # noqa: D101
        pass

    class vtkMRMLScalarVolumeNode:  # noqa: D101
        pass

    class Choice:
        """``slicer.parameterNodeWrapper.Choice``: the values a parameter may take."""

        def __init__(self, choices):
            self.choices = choices

    def parameterNodeWrapper(classtype):
        """``slicer.parameterNodeWrapper``: in Slicer it makes the class wrap a parameter node."""
        return classtype


KEEP_PRESET = "Slicer's own"
# volsr_core.hosts.slicer's preset_names(), SCALES and VARIANTS, and volsr_core.render.raycaster's DEVICES,
# spelled out: they are needed before volsr_core can be imported (tests/test_slicer_module.py compares them)
PRESETS = ("CT-Bone", "CT-AAA", "CT-Cardiac", "CT-Chest-Contrast-Enhanced", "CT-Soft-Tissue", "CT-Lung",
           "CT-Phantom", "MR-Default", "MR-Angio")
SCALES = (2, 4, 8)
VARIANTS = ("XS", "S", "M", "L")
DEVICES = ("cpu", "cuda")


#
# VolSRParameterNode
#
@parameterNodeWrapper
class VolSRParameterNode:
    """VolSR's settings, kept in the scene's VolSR parameter node (a vtkMRMLScriptedModuleNode, saved with
    the scene). Widgets of VolSR.ui whose ``SlicerParameterName`` names a setting follow it both ways.

    inputVolume - the scalar volume VolSR draws in the first 3D view (volume rendering is switched on for it).
    preset - the VolSR preset written into the volume's volume property node; KEEP_PRESET keeps Slicer's own.
    scale - upscaling factor: the volume is ray cast at 1/scale of the view's width and height.
    variant - network size: XS (fastest), S, M, L (best). The defaults, XS at 2x, are what pays off on a
        CPU: a better picture than rendering fewer pixels in the same time (docs/performance.md).
    device - where the ray caster and the network run.
    modelPath - an .onnx/.pt model file, which upscales by its own scale; "" for the shipped model of the
        variant at the scale.
    enabled - VolSR draws the 3D view (True) or Slicer does (False).
    """

    inputVolume: vtkMRMLScalarVolumeNode
    preset: Annotated[str, Choice((KEEP_PRESET, *PRESETS))] = KEEP_PRESET
    scale: Annotated[int, Choice(SCALES)] = 2  # volsr_core.runtime.models.DEFAULT_SCALE
    variant: Annotated[str, Choice(VARIANTS)] = "XS"  # volsr_core.runtime.models.default_variant(2)
    device: Annotated[str, Choice(DEVICES)] = "cpu"
    modelPath: str = ""
    enabled: bool = False


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
class VolSRWidget(ScriptedLoadableModuleWidget, VTKObservationMixin):
    """GUI bound to the scene's VolSRParameterNode: input volume, preset, scale, variant, device, model file
    and on/off. Every change of the parameter node is applied by ``VolSRLogic.apply``; the panel also
    shows the frame time of the last VolSR frame."""

    def __init__(self, parent=None):
        ScriptedLoadableModuleWidget.__init__(self, parent)
        VTKObservationMixin.__init__(self)  # observes the scene and the parameter node
        self.logic = None
        self.ui = None
        self._parameterNode = None
        self._parameterNodeGuiTag = None
        self._timer = None

    def setup(self) -> None:
        import ctk
        import qt

        ScriptedLoadableModuleWidget.setup(self)
        uiWidget = slicer.util.loadUI(self.resourcePath("UI/VolSR.ui"))
        self.layout.addWidget(uiWidget)
        self.ui = slicer.util.childWidgetVariables(uiWidget)
        uiWidget.setMRMLScene(slicer.mrmlScene)
        self.logic = VolSRLogic()

        # Slicer binds a ctkPathLineEdit to a pathlib.Path only, whose empty value reads ".": the model
        # file is bound by hand (onModelPathChanged, onParameterNodeModified); the rest by connectGui
        self.ui.modelPathLineEdit.filters = ctk.ctkPathLineEdit.Files
        self.ui.modelPathLineEdit.nameFilters = ["VolSR models (*.onnx *.pt)"]
        self.ui.modelPathLineEdit.connect("currentPathChanged(QString)", self.onModelPathChanged)

        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.StartCloseEvent, self.onSceneStartClose)
        self.addObserver(slicer.mrmlScene, slicer.mrmlScene.EndCloseEvent, self.onSceneEndClose)
        self._timer = qt.QTimer()
        self._timer.setInterval(500)  # ms: the frame time is refreshed twice a second while the module is shown
        self._timer.connect("timeout()", self.updateFrameTime)
        self.initializeParameterNode()  # also after "Reload"

    def cleanup(self) -> None:
        """The module is reloaded or Slicer closes: observers removed, VolSR off."""
        if self._timer is not None:
            self._timer.stop()
        self.removeObservers()
        if self.logic is not None:
            self.logic.cleanup()

    def enter(self) -> None:
        self.initializeParameterNode()
        self._timer.start()
        self.updateFrameTime()

    def exit(self) -> None:
        """Leaving the module: the GUI lets go of the parameter node; VolSR stays as it is."""
        self._timer.stop()
        self.setParameterNode(None)

    # the parameter node ------------------------------------------------------------------------------
    def initializeParameterNode(self) -> None:
        """Bind the GUI to the scene's VolSR parameter node (created when missing); pick the first scalar
        volume when none is chosen."""
        self.setParameterNode(self.logic.getParameterNode())
        if self._parameterNode.inputVolume is None:
            firstVolume = slicer.mrmlScene.GetFirstNodeByClass("vtkMRMLScalarVolumeNode")
            if firstVolume is not None:
                self._parameterNode.inputVolume = firstVolume

    def setParameterNode(self, parameterNode: VolSRParameterNode | None) -> None:
        """Bind the GUI to ``parameterNode`` (None: to nothing) and observe it, applying it at once."""
        if self._parameterNode is not None:
            self._parameterNode.disconnectGui(self._parameterNodeGuiTag)
            self.removeObserver(self._parameterNode, vtk.vtkCommand.ModifiedEvent, self.onParameterNodeModified)
        self._parameterNode = parameterNode
        self._parameterNodeGuiTag = None
        if parameterNode is not None:
            self._parameterNodeGuiTag = parameterNode.connectGui(self.ui)
            self.addObserver(parameterNode, vtk.vtkCommand.ModifiedEvent, self.onParameterNodeModified)
            self.onParameterNodeModified()

    def onParameterNodeModified(self, caller=None, event=None) -> None:
        """The model file field and the 3D view follow the parameter node; a failure is shown (VolSRLogic.apply
        has then switched VolSR off and unticked ``enabled``)."""
        import qt

        if self._parameterNode is None:
            return
        modelPath = self._parameterNode.modelPath
        if self.ui.modelPathLineEdit.currentPath != modelPath:
            self.ui.modelPathLineEdit.currentPath = modelPath
        error = None
        slicer.app.setOverrideCursor(qt.Qt.WaitCursor)
        try:
            self.logic.apply(self._parameterNode)
        except Exception as err:
            logging.exception("VolSR: the settings could not be applied")
            error = err
        finally:
            slicer.app.restoreOverrideCursor()
        self.ui.statusLabel.text = "" if error is None else f"Not applied: {error}"
        if error is not None:
            slicer.util.errorDisplay(f"VolSR: {error}")
        self.updateFrameTime()

    def onModelPathChanged(self, path: str) -> None:
        if self._parameterNode is not None:
            self._parameterNode.modelPath = path.strip()

    def onSceneStartClose(self, caller, event) -> None:
        """The scene (and its parameter node) goes away: let go of it, VolSR off."""
        self.setParameterNode(None)
        self.logic.cleanup()

    def onSceneEndClose(self, caller, event) -> None:
        if self.parent.isEntered:
            self.initializeParameterNode()

    def updateFrameTime(self) -> None:
        if self.ui is not None and self.logic is not None:
            self.ui.frameTimeLabel.text = self.logic.statusText()


#
# VolSRLogic
#
class VolSRLogic(ScriptedLoadableModuleLogic, VTKObservationMixin):
    """Switches VolSR on and off for a volume node in a 3D view; no GUI needed.

    ``apply(parameters)`` makes the 3D view show what a VolSRParameterNode says (the scene's own:
    ``getParameterNode()``). ``enable(volumeNode, scale=2, variant="XS")`` does it from plain arguments:
    it shows the node with volume rendering (if it was not), attaches VolSR to the 3D view's first
    renderer and returns the ``volsr_core.hosts.slicer.SlicerSession``; ``disable()`` gives the view
    back to Slicer.
    """

    def __init__(self, parent=None):
        ScriptedLoadableModuleLogic.__init__(self, parent)
        VTKObservationMixin.__init__(self)  # observes the volume node VolSR draws
        self.session = None
        self.volumeNode = None
        self.viewIndex = 0
        self.parameters = None  # the VolSRParameterNode apply() last followed
        self._settings = None  # enable()'s arguments VolSR was last started with by apply()
        self._preset = None  # (volume node, preset name) apply() last wrote

    def getParameterNode(self) -> VolSRParameterNode:
        """The scene's VolSR parameter node (created with the defaults when missing), typed."""
        return VolSRParameterNode(super().getParameterNode())

    def ensureDependencies(self) -> None:
        """VolSR's Python packages installed (asking first) and volsr_core importable (VolSRLib.bootstrap)."""
        bootstrap.ensureDependencies()

    kernelsCompiled = False  # in this Slicer session (class-wide: one logic per module reload, one cache per install)

    def compileKernels(self) -> None:
        """Numba compiles VolSR's kernels at their first use, about a minute on 2 cores after an install and a second
        from its disk cache later (``volsr_core.runtime.warmup``): done once per Slicer session before VolSR's first
        frame, under a wait cursor and a status message, instead of a silent pause in the 3D view's first render."""
        if VolSRLogic.kernelsCompiled:
            return
        import qt
        from volsr_core.runtime.warmup import compile_kernels

        slicer.util.showStatusMessage("VolSR: compiling its kernels (about a minute after an install, then a second)")
        qt.QApplication.setOverrideCursor(qt.Qt.WaitCursor)
        try:
            slicer.app.processEvents()
            compile_kernels()
        finally:
            qt.QApplication.restoreOverrideCursor()
            slicer.util.showStatusMessage("")
        VolSRLogic.kernelsCompiled = True

    # the parameter node ------------------------------------------------------------------------------
    @staticmethod
    def settingsFrom(parameters: VolSRParameterNode) -> dict:
        """``enable()``'s arguments from ``parameters`` (an empty model path: None, the shipped model of the
        variant at the scale; a model file: scale None, the model's own)."""
        model = parameters.modelPath.strip() or None
        return {"volumeNode": parameters.inputVolume, "scale": parameters.scale if model is None else None,
                "variant": parameters.variant, "model": model, "device": parameters.device}

    def apply(self, parameters: VolSRParameterNode):
        """Make the 3D view show what ``parameters`` say; returns the SlicerSession (None when off).

        The preset is written when it or the input volume changed (not for KEEP_PRESET). VolSR is
        (re)started when ``enabled`` and the settings differ from those it runs with, and switched off
        when not ``enabled``. Whenever VolSR is not running afterwards, ``parameters.enabled`` is set
        False (the GUI and the saved scene say so), and the error, if any, is raised.
        """
        self.parameters = parameters
        try:
            node = parameters.inputVolume
            preset = None if node is None or parameters.preset == KEEP_PRESET else (node, parameters.preset)
            if preset != self._preset:
                self._preset = preset  # first: a failing preset is not retried until it or the volume changes
                if preset is not None:
                    self.applyPreset(*preset)
            wanted = self.settingsFrom(parameters) if parameters.enabled else None
            if wanted != (self._settings if self.enabled else None):
                self.disable()
                if wanted is not None:
                    if node is None:
                        raise ValueError("choose an input volume first")
                    self.enable(**wanted)
                    self._settings = wanted
        finally:
            if parameters.enabled and not self.enabled:
                parameters.enabled = False
        return self.session

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
    def enable(self, volumeNode, scale: int | None = None, variant: str | None = None, model=None,
               preset: str | None = None, device: str = "cpu", viewIndex: int | None = None):
        """Draw ``volumeNode`` with VolSR in the 3D view; returns the SlicerSession. ``scale`` and ``variant``
        None: a model file's own scale, else the shipped XS 2x (the defaults)."""
        self.ensureDependencies()
        self.compileKernels()
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
        """VolSR off, and the parameter node forgotten (the scene closes or the module is unloaded)."""
        self.disable()
        self.parameters = None
        self._preset = None

    # following the node ------------------------------------------------------------------------------
    def _observeNode(self, node) -> None:
        for event in (slicer.vtkMRMLVolumeNode.ImageDataModifiedEvent,
                      slicer.vtkMRMLTransformableNode.TransformModifiedEvent):
            self.addObserver(node, event, self._onNodeChanged)

    def _unobserveNode(self) -> None:
        self.removeObservers(self._onNodeChanged)

    def _onNodeChanged(self, caller, event) -> None:
        if self.session is None or self.volumeNode is None:
            return
        try:
            self.session.set_volume(self.volumeFromNode(self.volumeNode))
        except Exception as err:  # e.g. a non-linear transform: Slicer draws it
            logging.error(f"VolSR: {err}; switched off")
            self.disable()
            if self.parameters is not None:
                self.parameters.enabled = False
        self.render()


def _sameVtkObject(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a is b or a.GetAddressAsString("vtkObject") == b.GetAddressAsString("vtkObject")


#
# VolSRTest
#
class VolSRTest(ScriptedLoadableModuleTest):
    """Self-test inside Slicer: the parameter node, and VolSR drawing a volume in the 3D view and giving it back."""

    def setUp(self):
        slicer.mrmlScene.Clear()

    def runTest(self):
        self.setUp()
        self.test_ras_to_lps()
        self.setUp()
        self.test_parameter_node()
        self.setUp()
        self.test_VolSR_draws_the_3D_view()

    # helpers -----------------------------------------------------------------------------------------
    def phantomVolumeNode(self, shape=(64, 64, 64)):
        """A scalar volume node holding VolSR's CT phantom, placed as our reader places it (LPS -> RAS)."""
        bootstrap.importVolsrCore()
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

    def privateParameterNode(self) -> VolSRParameterNode:
        """A VolSR parameter node of its own: the module's panel, if shown, follows only the scene's."""
        return VolSRParameterNode(slicer.mrmlScene.AddNewNodeByClass("vtkMRMLScriptedModuleNode", "VolSRTest"))

    def testModel(self):
        """None for the shipped default model (XS 2x), else an untrained S 4x one exported here (needs PyTorch)."""
        from volsr_core.errors import InputError
        from volsr_core.runtime.models import model_file

        try:
            model_file("XS", 2)
            return None
        except InputError:
            pass
        try:
            import torch

            from volsr_core.runtime.export import export_onnx
            from volsr_core.sr.network import SuperResolutionNet, variant_config
        except ImportError:
            self.skipTest("no shipped XS 2x model and no PyTorch to export an untrained one")
        torch.manual_seed(0)
        net = SuperResolutionNet(variant_config("S", 4, 0, taau_base=True)).eval()
        return str(export_onnx(net, Path(slicer.app.temporaryPath) / "VolSRTest-S4.onnx"))

    # tests -------------------------------------------------------------------------------------------
    def test_ras_to_lps(self):
        self.delayDisplay("RAS -> LPS")
        bootstrap.importVolsrCore()
        import numpy as np

        from volsr_core.hosts.slicer import ras_to_lps, volume_from_ijk_to_ras

        self.assertTrue(np.allclose(ras_to_lps([10.0, 20.0, 30.0]), [-10.0, -20.0, 30.0]))
        ijkToRas = np.array([[-0.8, 0, 0, 40.0], [0, -0.9, 0, 35.0], [0, 0, 1.2, -20.0], [0, 0, 0, 1]])
        volume = volume_from_ijk_to_ras(np.zeros((3, 4, 5), np.float32), ijkToRas)
        self.assertTrue(np.allclose(volume.direction, np.eye(3)))
        self.assertTrue(np.allclose(volume.origin, (-40.0, -35.0, -20.0)))
        self.assertTrue(np.allclose(volume.spacing, (0.8, 0.9, 1.2)))

    def test_parameter_node(self):
        self.delayDisplay("The parameter node")
        logic = VolSRLogic()
        scenes = logic.getParameterNode()
        self.assertIs(logic.getParameterNode().parameterNode, scenes.parameterNode, "one per scene")
        self.assertEqual(scenes.parameterNode.GetAttribute("ModuleName"), "VolSR")

        parameters = self.privateParameterNode()
        self.assertIsNone(parameters.inputVolume)
        self.assertEqual((parameters.preset, parameters.scale, parameters.variant, parameters.device,
                          parameters.modelPath, parameters.enabled), (KEEP_PRESET, 2, "XS", "cpu", "", False))
        parameters.scale = 8
        self.assertEqual(parameters.parameterNode.GetParameter("scale"), "8")  # in the node: saved with the scene
        with self.assertRaises(ValueError):
            parameters.scale = 3
        self.assertIsNone(logic.apply(parameters))  # off: nothing to do
        parameters.enabled = True
        with self.assertRaisesRegex(ValueError, "input volume"):
            logic.apply(parameters)
        self.assertFalse(parameters.enabled, "apply() unticks what it could not switch on")

    def test_VolSR_draws_the_3D_view(self):
        self.delayDisplay("VolSR in the 3D view")
        logic = VolSRLogic()
        logic.ensureDependencies()
        from volsr_core.scene.vtk_bridge import read_window

        node = self.phantomVolumeNode()
        model = self.testModel()
        slicer.app.layoutManager().setLayout(slicer.vtkMRMLLayoutNode.SlicerLayoutOneUp3DView)
        slicer.app.processEvents()
        parameters = self.privateParameterNode()
        parameters.inputVolume = node
        parameters.preset = "CT-Phantom"
        parameters.modelPath = model or ""
        parameters.enabled = True  # the shipped XS 2x: the defaults (an untrained model: its own scale)
        session = logic.apply(parameters)
        self.assertIs(logic.apply(parameters), session, "unchanged settings: no restart")
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
        parameters.enabled = False
        self.assertIsNone(logic.apply(parameters))
        view.forceRender()
        self.assertFalse(view.renderWindow().GetRenderers().IsItemPresent(overlay))
        self.assertEqual(vtkVolume.GetVisibility(), 1)
        self.assertEqual(logic.statusText(), "off")
        logic.cleanup()
        self.delayDisplay("Test passed")
