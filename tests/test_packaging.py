"""The distribution: one import root, ``stereocam``, and nothing generic at the top of site-packages."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from tests.support.paths import REPO

PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]


def _folder_of(package: str) -> Path:
    """Where pyproject's package-dir puts ``package``."""
    dirs = SETUPTOOLS["package-dir"]
    parts = package.split(".")
    for n in range(len(parts), 0, -1):
        root = ".".join(parts[:n])
        if root in dirs:
            return REPO / dirs[root] / Path(*parts[n:])
    raise AssertionError(f"{package} is under no package-dir root")


def _source_folders() -> set[Path]:
    """Every folder below a package-dir root, caches aside."""
    roots = [REPO / folder for folder in SETUPTOOLS["package-dir"].values()]
    return {d.resolve() for root in roots for d in [root, *root.rglob("*")]
            if d.is_dir() and "__pycache__" not in d.parts}


def test_no_package_list_is_kept_by_hand():
    assert "packages" not in SETUPTOOLS, "setup.py finds the packages; a hand-kept list goes stale"


@pytest.mark.slow
def test_the_wheel_installs_one_import_root(tmp_path):
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-v", "-w", str(tmp_path), str(REPO)],
                           capture_output=True, text=True, timeout=300)
    assert build.returncode == 0, build.stderr
    (wheel,) = tmp_path.glob("stereocam-*.whl")
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
        zf.extractall(tmp_path / "site")
    in_wheel = {_folder_of(".".join(Path(n).parent.parts)).resolve() for n in names if "dist-info" not in n}
    assert _source_folders() - in_wheel == set(), "source folders missing from the wheel"
    assert "stereocam/tools/viewer/static/viewer.js" in names
    assert "would be ignored" not in build.stderr + build.stdout
    tops = {n.split("/")[0] for n in names}
    assert {t for t in tops if not t.endswith(".dist-info")} == {"stereocam"}
    assert "stereocam/protocol/SPEC.md" in names
    # the unpacked wheel, not the source tree, answers ``import stereocam``
    code = ("import stereocam, stereocam.protocol, stereocam.device_sim, stereocam.tools.cli; "
            "print(stereocam.__file__); print(callable(stereocam.open), callable(stereocam.list_devices))")
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "site")}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    where, api = run.stdout.splitlines()
    assert Path(where).is_relative_to(tmp_path / "site") and api == "True True"
    for generic in ("host", "protocol", "tools", "device_sim"):
        assert not (tmp_path / "site" / generic).exists()
