"""SHA-256 of files: for model registries and checkpoints, and the key of numba kernels cached on disk (no third-party
imports)."""
from __future__ import annotations

import hashlib
import os
from types import ModuleType


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def sources_sha256(*modules: ModuleType) -> str:
    """Hex SHA-256 of the source files of ``modules`` (a set: order and repeats do not matter).

    What a numba kernel cached on disk (``cache=True``) closes over when it compiles in another module's code: the
    stages it inlines, the constants it reads. Numba keys its disk cache on the kernel's own file alone (numba issue
    1833), so after a change to a stage module (a ``git pull``, an edit) it would load the kernel's old machine code;
    it does hash a kernel's closure into the key, so a kernel that closes over this digest compiles anew instead.
    The helpers such a kernel calls are not cached apart: the kernel's cache holds their code, and a cache of their
    own would hold the old stages again (docs/architecture.md, "Where a change goes")."""
    digest = hashlib.sha256()
    for module in sorted(set(modules), key=lambda m: m.__name__):
        digest.update(f"{module.__name__} {file_sha256(module.__file__)}\n".encode())
    return digest.hexdigest()
