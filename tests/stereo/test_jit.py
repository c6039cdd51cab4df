"""numba's disk cache of the kernels is keyed on every module of the package (stereo/jit.py):
a kernel that inlined another module's function is rebuilt when that module changes."""
from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from stereocam.stereo import jit

KERNEL_MODULES = ("census", "postfilter", "prefilter", "sad", "sgm", "sgm_one_pass", "post.confidence",
                  "post.decimation", "post.holes", "post.lr_check", "post.median",
                  "post.spatial", "post.temporal")


@pytest.mark.parametrize("name", KERNEL_MODULES)
def test_every_cached_kernel_is_stamped_with_the_whole_package(name: str) -> None:
    mod = importlib.import_module(f"stereocam.stereo.{name}")
    kernels = [v for v in vars(mod).values()
               if isinstance(v, numba.core.registry.CPUDispatcher) and v._cache.cache_path]
    assert kernels, name
    for k in kernels:
        assert type(k._cache._impl.locator).__name__.startswith("Package"), (name, k)


def test_kernels_outside_the_package_that_inline_it_are_stamped_too() -> None:
    """tools/bench/sgm_profile.py's kernels call sgm.py's: keyed on their own file alone, a
    cached one kept the old census planes after the package changed, and crashed."""
    from stereocam.tools.bench import sgm_profile

    assert getattr(sgm_profile, jit.INLINES_PACKAGE) is True
    kernels = [v for v in vars(sgm_profile).values()
               if isinstance(v, numba.core.registry.CPUDispatcher)]
    assert len(kernels) >= 5
    for k in kernels:
        assert type(k._cache._impl.locator).__name__.startswith("Package"), k


CALLER = '''
import numba as nb
from .jit import KERNEL
from .callee import value

@nb.njit(**KERNEL)
def kernel():
    return value()
'''


def _run(root: Path) -> str:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # the cache beside the module
    out = subprocess.run([sys.executable, "-c", "import pk.caller as c; print(c.kernel())"],
                         cwd=root, capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_a_kernel_is_rebuilt_when_a_module_it_inlined_changes(tmp_path: Path) -> None:
    pk = tmp_path / "pk"
    pk.mkdir()
    (pk / "__init__.py").write_text("")
    shutil.copy(Path(jit.__file__), pk / "jit.py")
    (pk / "caller.py").write_text(CALLER)
    callee = "import numba as nb\n\n@nb.njit(cache=True)\ndef value():\n    return {}\n"
    (pk / "callee.py").write_text(callee.format(1))
    assert _run(tmp_path) == "1"
    assert list((pk / "__pycache__").glob("caller.kernel-*.nbi")), "not cached"
    first = (pk / "callee.py").stat().st_mtime_ns
    (pk / "callee.py").write_text(callee.format(2))
    # an edit seconds later, as a person makes one: Python's .pyc and numba's own index of the
    # callee key on its mtime (the .pyc in whole seconds) and size, the same here within a second
    os.utime(pk / "callee.py", ns=(first + 2_000_000_000, first + 2_000_000_000))
    assert _run(tmp_path) == "2"  # numba's own key (caller.py unchanged) would give 1
