"""VolSR's Python inside 3D Slicer: its requirements installed at first use, ``volsr_core`` imported.

Slicer's Python brings numpy, VTK and SimpleITK. The rest of what ``volsr_core`` needs is listed in
``Resources/requirements.txt`` beside VolSR.py; :func:`ensureDependencies` installs what is missing
with pip (asking first) the first time VolSR is used. ``volsr_core`` itself comes from an installed
``volsr`` or from the source checkout the module folder lies in (:func:`importVolsrCore`).

Everything here is plain Python except :func:`ensureDependencies`, which uses Slicer's pip helpers
(``slicer`` is imported inside it).
"""
from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
from pathlib import Path
from types import ModuleType

MODULE_DIR = Path(__file__).resolve().parents[1]  # the folder of VolSR.py (VolSRModule/ in a checkout)
REQUIREMENTS = MODULE_DIR / "Resources" / "requirements.txt"

_dependenciesReady = False  # set once ensureDependencies() succeeded in this Python process


def requirementLines(path: str | os.PathLike = REQUIREMENTS) -> list[str]:
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


def sourceCheckout(moduleDir: str | os.PathLike = MODULE_DIR) -> Path | None:
    """The VolSR source checkout the module folder lies in (its parent, holding ``volsr_core/``), if any."""
    root = Path(moduleDir).resolve().parent
    return root if (root / "volsr_core" / "__init__.py").is_file() else None


def importVolsrCore(moduleDir: str | os.PathLike = MODULE_DIR) -> ModuleType:
    """``volsr_core``: installed (pip), else from the source checkout around ``moduleDir``.

    From a checkout the repository root goes on ``sys.path``, and ``volsr_core.resources`` (which
    setup.py maps to the checkout's ``resources/``: presets, models) is registered from there.
    """
    try:
        return importlib.import_module("volsr_core")
    except ImportError:
        root = sourceCheckout(moduleDir)
        if root is None:
            raise ImportError("volsr_core is neither installed (pip install volsr) nor in a source checkout around "
                              f"{Path(moduleDir).resolve()}") from None
        if str(root) not in sys.path:
            sys.path.insert(0, str(root))
        importlib.invalidate_caches()
        return _withResources(importlib.import_module("volsr_core"))


def _withResources(core: ModuleType) -> ModuleType:
    """``core`` (imported from a checkout) with ``volsr_core.resources`` importable: the checkout's ``resources/``."""
    if "volsr_core.resources" in sys.modules:
        return core
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


def ensureDependencies() -> None:
    """Install what Resources/requirements.txt lists and is missing (asking first), then import volsr_core.

    Inside Slicer only. Slicer >= 5.9: ``slicer.packaging.pip_ensure`` (it asks, and offers a restart
    when an imported package was updated); before: the missing distributions are listed, confirmed
    (not when Slicer runs tests) and installed one by one with ``slicer.util.pip_install``.
    RuntimeError when something is still missing afterwards.
    """
    global _dependenciesReady
    if _dependenciesReady:
        return
    import slicer

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
    _dependenciesReady = True
