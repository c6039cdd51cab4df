"""URL schemes are an open table: the SDK never imports the simulator; the simulator registers itself."""
from __future__ import annotations

import subprocess
import sys
import types

import pytest

import stereocam
from stereocam import transports
from tests.support.paths import REPO


def test_the_sdk_source_never_names_the_simulator():
    offenders = [str(p.relative_to(REPO)) for p in (REPO / "host").rglob("*.py") if "device_sim" in p.read_text()]
    assert offenders == []


def _run(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd="/")
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


def test_importing_and_listing_does_not_load_the_simulator():
    out = _run("import sys, stereocam; stereocam.list_devices(); "
               "print(sorted(m for m in sys.modules if 'device_sim' in m))")
    assert out == "[]"


def test_sim_urls_reach_the_simulator_through_its_entry_point():
    out = _run("import sys, stereocam\n"
               "with stereocam.open('sim://?seed=4') as cam: print(cam.info().serial)\n"
               "print('stereocam.device_sim' in sys.modules)")
    assert out.splitlines() == ["SIM00004", "True"]


def test_a_registered_scheme_gets_its_urls(monkeypatch):
    opened = []
    fake = types.ModuleType("tests_fake_scheme")
    fake.open_transport = lambda url, timeout: opened.append((url, timeout)) or "transport"
    fake.discover = lambda: ["entry"]
    fake.reopen_url = lambda url, serial: f"fake://?serial={serial}"
    monkeypatch.setitem(sys.modules, "tests_fake_scheme", fake)
    monkeypatch.setitem(transports.SCHEMES, "fake", "tests_fake_scheme")
    assert transports.open_transport("FAKE://x?y=1", 0.25) == "transport"
    assert opened == [("FAKE://x?y=1", 0.25)]
    assert "entry" in transports.discover()
    assert transports.reopen_url("fake://a", "SN9") == "fake://?serial=SN9"


def test_a_discovery_source_that_fails_does_not_hide_the_others(monkeypatch):
    broken = types.ModuleType("tests_broken_scheme")

    def boom():
        raise OSError("bus on fire")

    broken.discover = boom
    monkeypatch.setitem(sys.modules, "tests_broken_scheme", broken)
    monkeypatch.setitem(transports.SCHEMES, "broken", "tests_broken_scheme")
    from stereocam.device_sim import SimulatedCamera

    with SimulatedCamera(serial="DISC-1", seed=1):
        assert any(e.serial == "DISC-1" for e in stereocam.list_devices())


@pytest.mark.parametrize("url", ["", None, 5])
def test_a_url_that_is_not_a_string_is_a_config_error(url):
    """A usage mistake, as stereocam.open calls it (a TransportError is a link's failure)."""
    with pytest.raises(stereocam.ConfigError, match="non-empty string"):
        transports.open_transport(url)


def test_a_plugin_joins_discovery_only_once_its_package_is_imported():
    from stereocam.transports import plugins

    assert plugins.provider("stereocam.device_sim.links.inprocess") == "stereocam.device_sim"
    assert plugins.provider("acme_cams.scheme") == "acme_cams"
    out = _run("import sys, stereocam.transports.plugins as p\n"
               "print(sorted(p.declared(p.URL_SCHEMES)), sorted(p.in_use(p.URL_SCHEMES)))\n"
               "import stereocam.device_sim\n"
               "print(sorted(p.in_use(p.URL_SCHEMES)), sorted(p.in_use(p.USB_BACKENDS)))")
    assert out.splitlines() == ["['replay', 'sim'] []", "['replay', 'sim'] ['sim']"]
HOSTILE_URLS = ["spy://17.0.0.1:1[", "socket://[::1", "spy://17.]0.0.1:1", "spy://17.[0].0.1:1",
                "rfc2217://12@[7.0.0].1:1", "rfc2217://[zz]:1", "usb://[", "sim://[?serial=x", "replay://[",
                "loop://[", "replay:///no\x00where.mcap", "socket://\udcff:1", "usb://\udcff", "\udcff://x"]


@pytest.mark.parametrize("url", HOSTILE_URLS)
def test_a_malformed_url_raises_a_typed_error_naming_it(url):
    """Issue 22.9: whatever the URL, opening it raises a StereoCamError (never a bare ValueError or
    UnicodeError from the URL parser)."""
    with pytest.raises(stereocam.StereoCamError) as err:
        stereocam.open(url, timeout=0.2).close()
    assert err.value.__class__.__module__.startswith("stereocam")


def test_the_info_tool_says_what_is_wrong_with_a_malformed_url_without_a_traceback():
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "info", "socket://[::1"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode != 0 and "Traceback" not in r.stderr and "socket://[::1" in r.stderr


@pytest.mark.parametrize("url", ["tcp://127.0.0.1:5555", "foo://x", "a.b://x", "a-b://x"])
def test_a_scheme_nothing_handles_is_a_config_error_listing_the_known_ones(url):
    with pytest.raises(stereocam.ConfigError, match=r"known: .*sim, socket, .*usb.*socket://HOST:PORT"):
        stereocam.open(url, timeout=0.2)
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "info", url],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "no transport for" in r.stderr
