"""``import stereocam`` loads nothing: the public names are imported on first use (PEP 562)."""
from __future__ import annotations

import subprocess
import sys

import pytest

import stereocam


def _loaded_after(code: str) -> list[str]:
    """The ``stereocam`` modules a fresh interpreter holds after running ``code``."""
    probe = f"{code}\nimport sys\nprint(' '.join(sorted(m for m in sys.modules if m.startswith('stereocam'))))"
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd="/")
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


@pytest.mark.parametrize("code", ["import stereocam.protocol", "import stereocam.protocol.framing",
                                  "from stereocam.protocol import messages"])
def test_the_protocol_loads_no_sdk_module(code):
    outside = [m for m in _loaded_after(code) if m != "stereocam" and not m.startswith("stereocam.protocol")]
    assert outside == []


def test_importing_the_package_loads_no_submodule():
    assert _loaded_after("import stereocam") == ["stereocam"]


def test_a_public_name_loads_its_module_on_first_use():
    loaded = _loaded_after("import stereocam\nassert callable(stereocam.open)")
    assert "stereocam.camera" in loaded and "stereocam.recording" not in loaded


def test_every_public_name_resolves_and_is_listed_by_dir():
    for name in stereocam.__all__:
        assert getattr(stereocam, name) is not None, name
    assert set(stereocam.__all__) <= set(dir(stereocam))
    assert set(stereocam.__all__) == {"__version__", *stereocam._EXPORTS}
    assert stereocam.ConfigError.__module__ == "stereocam.protocol.errors"
    assert stereocam.open.__module__ == "stereocam.camera"


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no_such_name"):
        stereocam.no_such_name  # noqa: B018 - the attribute access is the test
    assert not hasattr(stereocam, "no_such_module")


def test_submodules_stay_reachable_as_attributes():
    assert stereocam.transports.open_transport.__module__ == "stereocam.transports"
