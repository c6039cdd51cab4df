"""A feature whose optional dependency group is not installed says which pip extra brings it."""
from __future__ import annotations

import subprocess
import sys

import pytest

from stereocam.protocol.errors import MissingExtraError, StereoCamError
from stereocam.protocol.extras import EXTRA_OF, raise_missing


def _without(module: str, code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter where ``module`` cannot be imported."""
    probe = f"import sys\nsys.modules[{module!r}] = None\n{code}"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd="/")


@pytest.mark.parametrize("module, code, extra", [
    ("numba", "import stereocam.device_sim", "sim"),
    ("mcap", "import stereocam.recording", "recording"),
])
def test_a_missing_extra_is_named(module, code, extra):
    run = _without(module, code)
    assert run.returncode != 0
    assert "MissingExtraError: " in run.stderr and f"pip install 'stereocam[{extra}]'" in run.stderr


def test_the_sdk_opens_cameras_without_any_extra():
    blocked = "\n".join(f"sys.modules[{m!r}] = None" for m in EXTRA_OF)
    run = _without("numba", f"{blocked}\nimport stereocam\nprint(stereocam.Camera.__name__, stereocam.list_devices())")
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("Camera [")


def test_a_command_whose_extra_is_missing_says_which():
    run = _without("cv2", "from stereocam.tools.cli import main\nraise SystemExit(main(['capture', '--help']))")
    assert run.returncode != 0
    assert "stereocam capture: error: this command needs the 'cv2' package: pip install 'stereocam[viewer]'" \
        in run.stderr


def test_a_missing_module_of_no_extra_is_left_alone():
    with pytest.raises(ModuleNotFoundError) as caught:
        raise_missing(ModuleNotFoundError("no", name="stereocam.nonexistent"), "x")
    assert not isinstance(caught.value, MissingExtraError)
    with pytest.raises(MissingExtraError) as named:
        raise_missing(ModuleNotFoundError("no", name="psycopg.pq"), "the factory record")
    assert isinstance(named.value, (StereoCamError, ImportError)) and "stereocam[factory]" in str(named.value)
