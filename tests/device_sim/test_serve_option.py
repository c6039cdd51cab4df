"""``stereocam sim --serve``: a spec that cannot be served is a usage error (exit 2, one line, no
traceback), found before the simulator is built (that is slow: the matcher compiles)."""
from __future__ import annotations

import socket

import pytest

from stereocam.device_sim import __main__ as sim_main
from stereocam.device_sim.links.servers import TcpServer
from stereocam.protocol.errors import ConfigError
from stereocam.tools import cli


@pytest.mark.parametrize("spec, words", [
    ("tcp:127.0.0.1:99999", "the port must be 0..65535"), ("tcp:127.0.0.1:65536", "the port must be 0..65535"),
    ("tcp:127.0.0.1:²", "tcp:HOST:PORT expected"), ("tcp:127.0.0.1:-1", "tcp:HOST:PORT expected"),
    ("tcp::80", "tcp:HOST:PORT expected"), ("udp:1", "'pty' or 'tcp:HOST:PORT'")])
def test_a_bad_serve_spec_is_refused_before_the_simulator_is_built(monkeypatch, capsys, spec: str, words: str):
    def built(*args: object, **kwargs: object) -> None:
        raise AssertionError("the simulator was built before --serve was checked")

    monkeypatch.setattr(sim_main, "SimulatedCamera", built)
    monkeypatch.setattr(sim_main, "free_seed", built)
    assert cli.main(["sim", "--serve", spec]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and len(err.strip().splitlines()[-1]) < 200


@pytest.mark.parametrize("port", [-1, 65536, 99999, True, "80"])
def test_a_tcp_server_refuses_a_port_outside_0_to_65535(port: object):
    with pytest.raises(ConfigError, match="0..65535"):
        TcpServer(None, "127.0.0.1", port)  # type: ignore[arg-type]  # refused before the sim is used


def test_a_port_that_is_taken_is_a_usage_error(monkeypatch, capsys):
    """The bind fails after the unit is built: a usage error all the same, and the unit is closed."""
    closed = []

    class Unit:
        def close(self) -> None:
            closed.append(True)

    monkeypatch.setattr(sim_main, "SimulatedCamera", lambda **kwargs: Unit())
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        assert cli.main(["sim", "--seed", "3", "--serve", f"tcp:127.0.0.1:{port}"]) == 2
    err = capsys.readouterr().err
    assert "cannot listen there" in err and "Traceback" not in err and closed == [True]
