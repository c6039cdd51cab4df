"""The numba options the kernels are compiled with, typed so ``njit(**KERNEL)`` checks, and
the disk cache's key: every kernel module imports this one before it defines a kernel."""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Literal, TypedDict


class JitOptions(TypedDict, total=False):
    """The ``numba.njit`` keywords the kernels set."""

    nogil: bool
    cache: bool
    boundscheck: bool
    error_model: Literal["python", "numpy"]


KERNEL: JitOptions = {"nogil": True, "cache": True, "boundscheck": False}
"""Without the GIL (callers run kernels on threads), cached on disk, no bounds checks."""

C_ARITHMETIC: JitOptions = {**KERNEL, "error_model": "numpy"}
"""``KERNEL`` with C's integer division (no zero-division check), as the matching kernels need."""


def _sources_digest(folder: Path) -> bytes:
    """SHA-256 over every .py file under folder (names and contents, in a fixed order)."""
    h = hashlib.sha256()
    for path in sorted(folder.rglob("*.py")):
        h.update(str(path.relative_to(folder)).encode() + b"\0" + path.read_bytes() + b"\0")
    return h.digest()


PACKAGE = Path(__file__).resolve().parent
"""This package's folder: its kernels call each other across modules."""


INLINES_PACKAGE = "STEREO_KERNELS_INLINED"
"""A module outside the package whose cached kernels call the package's sets this global to
True (tools/bench/sgm_profile.py): its kernels are stamped with the package's digest too."""


def _stamp_with_package(locator_cls: Any) -> Any:
    """locator_cls whose source stamp also covers every module of the package."""
    class PackageLocator(locator_cls):
        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if PACKAGE not in Path(py_file).resolve().parents \
                    and py_func.__globals__.get(INLINES_PACKAGE) is not True:
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self) -> Any:
            return (super().get_source_stamp(), _DIGEST)

    PackageLocator.__name__ = f"Package{locator_cls.__name__}"
    return PackageLocator


def _register_locators() -> None:
    """numba keys a kernel's disk cache on its own file only, so a cached kernel would keep
    the code it inlined from another module (sgm.py's from postfilter.py, sgm_simd.py, ...)
    after that module changed: in a developer's tree and in an upgraded install, whose
    __pycache__ outlives the files pip replaces. Registered first, these locators (numba's
    own, same cache folders) stamp each of this package's kernels with the digest of all its
    modules, so any change rebuilds them."""
    from numba.core import caching
    impl = getattr(caching, "CacheImpl", None)
    if impl is None:  # numba < 0.61
        impl = caching.__dict__["_CacheImpl"]
    ours = [_stamp_with_package(getattr(caching, name)) for name in
            ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")]
    impl._locator_classes = ours + [c for c in impl._locator_classes
                                    if not c.__name__.startswith("Package")]


_DIGEST = _sources_digest(PACKAGE)
_register_locators()
