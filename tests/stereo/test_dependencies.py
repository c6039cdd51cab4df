"""stereocam.stereo sits at the level of the protocol: it imports stereocam.protocol, numpy, numba and
the standard library only (no SDK module, nothing of the simulator), and its package imports lazily."""
from __future__ import annotations

import ast
import subprocess
import sys

from tests.support.paths import REPO

# llvmlite: numba's own IR (intrinsics)
ALLOWED = ("stereocam.protocol", "stereocam.stereo", "numpy", "numba", "llvmlite")


def _imports(path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def test_the_engines_import_the_protocol_numpy_and_numba_only() -> None:
    files = sorted((REPO / "host" / "stereo").glob("*.py"))
    assert len(files) > 10
    for path in files:
        for name in _imports(path):
            top = name.split(".")[0]
            assert name.startswith(ALLOWED) or (top != "stereocam" and top in sys.stdlib_module_names), \
                f"{path.name} imports {name}"


def test_the_package_imports_nothing_heavy_until_used() -> None:
    code = ("import sys, stereocam.stereo as s; heavy = 'stereocam.stereo.sad' in sys.modules; "
            "s.MatchParams; print(heavy, 'stereocam.stereo.matcher' in sys.modules, "
            "any(n.startswith('stereocam.device_sim') for n in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False", "False"]
