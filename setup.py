"""Packages are found from the folders, not kept by hand: every folder below each ``package-dir`` root
of pyproject.toml (``host`` is ``stereocam``, ``protocol`` is ``stereocam.protocol``, ...) is a package,
data folders such as ``tools/viewer/static`` included, so a new subpackage always lands in the wheel."""
from __future__ import annotations

import sys
from pathlib import Path

from setuptools import find_namespace_packages, setup

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10 builds with the backport (build-system.requires)
    import tomli as tomllib

ROOTS: dict[str, str] = tomllib.loads(Path(__file__).with_name("pyproject.toml").read_text())["tool"]["setuptools"][
    "package-dir"]


def packages() -> list[str]:
    """Each root and every folder beneath it, as dotted package names."""
    found = []
    for name, folder in ROOTS.items():
        found.append(name)
        found += [f"{name}.{sub}" for sub in find_namespace_packages(where=folder, exclude=["*__pycache__*"])]
    return found


setup(packages=packages())
