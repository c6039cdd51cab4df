"""stereocam view URL: serve the live viewer on a local port and open it in the browser."""
from __future__ import annotations

import contextlib
import secrets
import signal
import threading
import webbrowser
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import click

import stereocam
from stereocam.tools.camera.session import output_dir, preserved_configuration
from stereocam.tools.options import CONTEXT, SETTING, epilog

from .group_session import GroupViewerSession
from .rerun_bridge import RerunBridge, rerun_available
from .server import ViewerServer, token_problem
from .session import ViewerSession


RERUN_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")  # what rerun-sdk connects to


def _interrupt(signum: int, frame: object) -> None:  # noqa: ARG001
    raise KeyboardInterrupt


def _rerun_save(ctx: click.Context, param: click.Parameter, value: Path | None) -> Path | None:
    """``--rerun-save``: a file in a folder that exists (Rerun creates the file, never the folder)."""
    if value is not None and not value.parent.is_dir():
        raise click.BadParameter(f"{value.parent} is not a folder")
    return value


def _rerun_connect(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """``--rerun-connect``: a URL of a scheme Rerun connects to."""
    if value is not None and not value.startswith(RERUN_SCHEMES):
        raise click.BadParameter(f"expected a URL starting {', '.join(RERUN_SCHEMES)}, e.g. "
                                 f"rerun+http://127.0.0.1:9876/proxy, got {value!r}")
    return value


def _token(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """``--token``: some text ('auto': a random one); an empty one would turn the check off, and one
    with a space, ';' or '&' would not survive the printed address or the cookie."""
    if value is not None and not value.strip():
        raise click.BadParameter("must not be empty: give the token, or 'auto' for a random one")
    why = None if value is None else token_problem(value)
    if why:
        raise click.BadParameter(why)
    return value


@click.command("view", context_settings=CONTEXT,
               epilog=epilog("Exit codes: 0 stopped with Ctrl-C once serving (130 if interrupted before); 2 also "
                             "a port that is taken."))
@click.argument("urls", nargs=-1, required=True, metavar="URL [URL...]")
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Local port to serve on (0: any free port).")
@click.option("--host", default="127.0.0.1", show_default=True, help="Address to listen on.")
@click.option("--no-browser", is_flag=True, help="Do not open the browser; just print the address.")
@click.option("--keep-config", is_flag=True, help="Leave the configuration changed in the viewer on the camera.")
@click.option("--record-dir", type=click.Path(file_okay=False, writable=True, path_type=Path), default=".",
              show_default=True, help="Folder for the recordings started with the page's Record button.")
@click.option("--master", default="0", show_default=True, metavar="INDEX|none",
              help="With several URLs: which camera (0 = the first) drives the trigger line; 'none' when "
                   "a generator or a unit outside the group drives it.")
@click.option("--allow-host", "allow_hosts", multiple=True, metavar="NAME",
              help="A host name the viewer answers to besides localhost and IP addresses (repeatable; "
                   "for a viewer reached by name over a network).")
@click.option("--token", default=None, metavar="TEXT|auto", callback=_token,
              help="Answer only requests that carry this token ('auto': a random one); the printed "
                   "address carries it. Advised with --host 0.0.0.0.")
@click.option("--set", "settings", type=SETTING, multiple=True,
              help="Configure every camera before viewing (repeatable), e.g. --set fps=5 --set gain=40.")
@click.option("--rerun", "rerun_spawn", is_flag=True,
              help="Also stream the images, depth with the pinhole model, point cloud and counters to Rerun "
                   "(rerun-sdk): to a Rerun viewer it starts, unless --rerun-save or --rerun-connect.")
@click.option("--rerun-save", type=click.Path(dir_okay=False, writable=True, path_type=Path), default=None,
              callback=_rerun_save, metavar="FILE.rrd", help="Stream to Rerun into this .rrd file (implies --rerun).")
@click.option("--rerun-connect", default=None, metavar="URL", callback=_rerun_connect,
              help="Stream to the Rerun viewer at URL, e.g. rerun+http://127.0.0.1:9876/proxy (implies --rerun).")
def command(urls: tuple[str, ...], port: int, host: str, no_browser: bool, keep_config: bool,
            record_dir: Path, master: str, allow_hosts: tuple[str, ...], token: str | None,
            settings: tuple[tuple[str, int], ...], rerun_spawn: bool, rerun_save: Path | None,
            rerun_connect: str | None) -> int:
    """Live viewer: left, right and disparity (colour bar in metres), a 3-D view of the point cloud,
    a depth histogram with a near/far range, depth and 3-D point under the cursor, frame rate and
    counters with rates, the configuration in groups with the device's ranges and named choices
    (always the camera's values; a refused one snaps back with the reason), reset to defaults and
    presets, trigger, start/stop, snapshots (PNG, 16-bit PNG, .npy, PLY), recording to MCAP;
    --rerun also streams to Rerun. With several URLs: a camera group on one external trigger line
    (the first camera drives it, see --master), shown as matched sets with the spread of their
    capture times, each head's clock-map error and the sets a head missed, with start/stop, one
    set on demand and settings for every head. The first line printed is the viewer's address.
    Runs until Ctrl-C; then each camera's configuration is put back as found unless --keep-config."""
    master_index = _master_index(master, len(urls))  # with one URL too: 0 or 'none', else a usage error
    access = Access(allow_hosts, secrets.token_urlsafe(18) if token == "auto" else token)
    rerun = rerun_spawn or rerun_save is not None or rerun_connect is not None
    if rerun and len(urls) > 1:
        raise click.UsageError("--rerun streams one camera; give one URL")
    if rerun and not rerun_available():
        raise click.UsageError("--rerun needs rerun-sdk: pip install 'stereocam[viewer]'")
    if len(urls) > 1:
        return _view_group(list(urls), port, host, no_browser, keep_config, master_index,
                           access, dict(settings))
    output_dir(record_dir, "--record-dir")  # made and written into now, not when Record is pressed
    with stereocam.open(urls[0], timeout=2.0) as cam, \
            (contextlib.nullcontext() if keep_config else preserved_configuration(cam)):
        if settings:
            cam.configure(**dict(settings))
        session = ViewerSession(cam, record_dir)
        try:
            bridge = RerunBridge(session, rerun_save, rerun_connect) if rerun else None
        except BaseException:  # Rerun refused the sink (RerunSinkError: exit 1): no grab thread left behind
            session.close()
            raise
        try:
            _serve(session, host, port, no_browser, cam.start, access)
        finally:
            if bridge is not None:
                bridge.close()
    return 0


def _master_index(text: str, cameras: int) -> int | None:
    if text.strip().lower() == "none":
        return None
    if not text.strip().isdecimal() or int(text) >= cameras:
        raise click.BadParameter(f"expected 0..{cameras - 1} (a camera's place among the URLs) or 'none', got {text!r}",
                                 param_hint="'--master'")
    return int(text)


def _view_group(urls: list[str], port: int, host: str, no_browser: bool, keep_config: bool,
                master: int | None, access: Access, config: dict[str, int]) -> int:
    found = {}
    if not keep_config:
        for url in urls:
            with stereocam.open(url, timeout=2.0) as cam:
                found[url] = cam.config()
    try:
        with stereocam.CameraGroup(urls, config=config, master=master, timeout=5.0) as group:
            _serve(GroupViewerSession(group), host, port, no_browser, lambda: None, access)
    finally:
        for url, config in found.items():  # each head as found (the group put it on external trigger)
            with stereocam.open(url, timeout=2.0) as cam:
                cam.configure(**config)
    return 0


@dataclass(frozen=True)
class Access:
    """Who the viewer answers: the host names besides loopback and IP addresses, and its token."""

    allowed_hosts: tuple[str, ...] = ()
    token: str | None = None


def _serve(session: ViewerSession | GroupViewerSession, host: str, port: int, no_browser: bool,
           start: Callable[[], object], access: Access) -> None:
    try:
        server = ViewerServer(session, host, port, access.allowed_hosts, access.token)
    except OSError as exc:
        session.close()
        raise click.BadParameter(f"cannot listen on {host}:{port}: {exc.strerror or exc}",
                                 param_hint="'--port'") from exc
    address = server.url + (f"?token={access.token}" if access.token else "")
    click.echo(address)
    if not no_browser:
        threading.Thread(target=webbrowser.open, args=(address,), daemon=True).start()
    signal.signal(signal.SIGTERM, _interrupt)  # a service manager's stop is a Ctrl-C too
    try:
        start()
        server.serve_forever(poll_interval=0.2)
    except KeyboardInterrupt:
        click.echo("viewer stopped", err=True)
    finally:
        server.server_close()
        session.close()
