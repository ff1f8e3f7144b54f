"""Put a virtual environment's packages in front of ParaView's own, from inside pvpython (standard library only).

ParaView 5.11's ``pvpython`` has no ``--venv`` option (5.12 added one), and ``PYTHONPATH`` alone does not run
the ``.pth`` files that an editable install of VolSR relies on. :func:`activate` does what ``site`` does for
a venv: it adds the venv's site-packages with :func:`site.addsitedir` (``.pth`` files included) and moves
what it added to the front of ``sys.path``, so the venv's pins win over Debian's packages while everything
the venv lacks (numpy, ``paraview``, ``vtkmodules``) still comes from ParaView's Python.

The venv (``make paraview-env``, docs/paraview.md) is Debian's Python 3.11 with ``--system-site-packages``,
holding VolSR and onnxruntime and no pip ``vtk``: ParaView's own VTK must serve.
"""
from __future__ import annotations

import os
import site
import sys
from pathlib import Path

ENV_VARIABLE = "VOLSR_PARAVIEW_VENV"
DEFAULT_NAME = ".venv-paraview"


def site_packages(venv: str | os.PathLike) -> Path:
    """The venv's site-packages for this interpreter's Python version (an error naming it when absent)."""
    root = Path(venv).expanduser().resolve()
    folder = root / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"
    if not folder.is_dir():
        found = sorted(p.name for p in (root / "lib").glob("python*")) if (root / "lib").is_dir() else []
        have = f" (it has {', '.join(found)})" if found else ""
        raise RuntimeError(f"{root}: not a venv for Python {sys.version_info[0]}.{sys.version_info[1]}, the Python "
                           f"this ParaView runs{have}; build it with `make paraview-env`")
    if (folder / "vtkmodules").is_dir():
        raise RuntimeError(f"{folder}: holds a pip-installed vtk, which would replace ParaView's own VTK; "
                           "uninstall it (pip uninstall vtk)")
    return folder


def find_venv(explicit: str | os.PathLike | None = None, near: str | os.PathLike | None = None) -> Path | None:
    """The venv to use: ``explicit``, else ``$VOLSR_PARAVIEW_VENV``, else ``.venv-paraview`` in ``near`` or one of
    its parents (the repository a script or plugin lives in); None when there is none."""
    if explicit:
        return Path(explicit)
    if os.environ.get(ENV_VARIABLE):
        return Path(os.environ[ENV_VARIABLE])
    if near is not None:
        for folder in [Path(near).resolve(), *Path(near).resolve().parents]:
            if (folder / DEFAULT_NAME / "pyvenv.cfg").is_file():
                return folder / DEFAULT_NAME
    return None


def activate(venv: str | os.PathLike) -> Path:
    """Put ``venv``'s site-packages (and what its ``.pth`` files add) at the front of ``sys.path``; returns it.

    Calling it again for the same venv changes nothing.
    """
    folder = site_packages(venv)
    if str(folder) in sys.path:
        return folder
    before = list(sys.path)
    site.addsitedir(str(folder))
    added = [p for p in sys.path if p not in before]
    sys.path[:] = added + before
    return folder


def fix_python_plugins() -> None:
    """Let ParaView 5.11 load Python plugins under Python 3.11 (Debian 12's ParaView).

    Its plugin loader, ``paraview/detail/pythonalgorithm.py`` (behind ``paraview.util.vtkAlgorithm``), does
    ``from inspect import getargspec``, which Python 3.11 removed, so ``LoadPlugin`` of any Python plugin
    fails with "Failed to import `paraview.detail.pythonalgorithm`". This puts ``inspect.getargspec``
    back as ``getfullargspec`` (the loader reads only ``.args``); nothing happens where it exists.
    """
    import inspect

    if not hasattr(inspect, "getargspec"):
        inspect.getargspec = inspect.getfullargspec
