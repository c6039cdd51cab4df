"""The viewer's HTTP server: the static page, the newest JPEG per plane, JSON for state and actions.

GET  /                      the page (static/index.html, viewer.js, viewer.css)
GET  /api/state             identity, rates, host and device counters, configuration with ranges
GET  /api/frame?after=SEQ   the newest frame's metadata (waits up to 1 s for one newer than SEQ)
GET  /image/PLANE.jpg       the newest frame's left, right or colour-mapped disparity as JPEG
GET  /api/point?x=&y=       disparity, depth and 3-D point under the cursor
GET  /api/points.bin?step=&colour=depth|left  the newest frame's point cloud for the 3-D view
                            (u32 count, x y z float32 each, r g b bytes each)
POST /api/config            {"name": value, ...}; a refusal answers 409 with the device's reason
                            and the configuration the camera kept
                            (every POST: JSON, same origin, at most MAX_BODY bytes, else 415/403/413)
POST /api/config/reset      every setting to its default
POST /api/preset/save|load  {"name": NAME}: the configuration to/from --record-dir/NAME.preset.json
POST /api/range             {"near_m": N, "far_m": F} (or nulls): the colour map's and histogram's range
POST /api/start|stop|trigger
POST /api/record/start|stop every frame to an MCAP file in the viewer's --record-dir (its path answered)
GET  /snapshot/NAME         the newest frame as left.png, right.png, disparity.png (depth colour bar),
                            disparity.npy (raw int16), disparity16.png (uint16, 1/16 px, 0 invalid)
                            or points.ply (?colour=depth|left), as a download

A camera group (``GroupViewerSession``) has its own page instead:
GET  /                      static/group.html (group.js, viewer.css)
GET  /api/group/state       every head (name, URL, clock-map error), set counts, the sets a head missed
GET  /api/group/set?after=T the newest matched set after trigger T: skew, each frame's offset
GET  /image/CAMERA/PLANE.jpg  a head's left or colour-mapped disparity image: its last frame (the
                            newest set's, or the one it had before it missed)
POST /api/group/config      {"name": value, ...} on every head (a refusal names the head, changes none)
POST /api/group/start|stop  every head (the master last on start, first on stop)
POST /api/group/trigger     one matched set from a stopped group (start, the master's first pulse, stop)
"""
from __future__ import annotations

import hmac
import ipaddress
import json
import logging
import socket
import threading
from http.cookies import SimpleCookie
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any, Iterable
from urllib.parse import parse_qs, urlsplit

import stereocam
from stereocam.recording import RecordingError
from .cloud import cloud_bytes, sampled_points
from .group_session import GroupViewerSession
from .session import ViewerSession
from .snapshots import MEDIA, SNAPSHOTS, MissingSnapshot, snapshot

STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/viewer.js": ("viewer.js", "text/javascript"),
          "/cloud3d.js": ("cloud3d.js", "text/javascript"), "/settings.js": ("settings.js", "text/javascript"),
          "/viewer.css": ("viewer.css", "text/css")}
GROUP_STATIC = {"/": ("group.html", "text/html; charset=utf-8"), "/group.js": ("group.js", "text/javascript"),
                "/settings.js": ("settings.js", "text/javascript"), "/viewer.css": ("viewer.css", "text/css")}
MAX_BODY = 64 * 1024  # bytes of a POST body: a configuration is a few hundred
_log = logging.getLogger(__name__)


LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")
TOKEN_COOKIE = "stereocam_viewer_token"
CONNECTION_TIMEOUT_S = 15.0  # a connection silent this long (half-sent request, idle keep-alive) is closed
MAX_CONNECTIONS = 32  # connections served at once; more are answered 503 and closed
REFUSAL_LINGER_S = 0.2  # how long a refused connection's request is read before it is closed


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not a number a setting can take")


def _settings(body: dict[str, Any]) -> dict[str, int]:
    """``body`` as parameter settings: every value an integer (not true, 320.7 or 1e400)."""
    for name, value in body.items():
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name}: {json.dumps(value)[:40]} is not an integer")
    return body


class ViewerServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, session: ViewerSession | GroupViewerSession, host: str = "127.0.0.1", port: int = 0,
                 allowed_hosts: Iterable[str] = (), token: str | None = None,
                 max_connections: int = MAX_CONNECTIONS):
        """``allowed_hosts``: host names (besides loopback names and IP addresses) a request's Host
        may carry, for a viewer reachable from a network; ``token``: if given, every request must
        carry it (``?token=`` once, then the cookie the page gets; or ``Authorization: Bearer``)."""
        self.session = session
        self.allowed_hosts = {h.lower() for h in (*LOOPBACK_NAMES, *allowed_hosts)}
        self.token = token
        self._slots = threading.BoundedSemaphore(max_connections)
        super().__init__((host, port), _Handler)

    def process_request(self, request: Any, client_address: Any) -> None:
        """At most ``max_connections`` at once: one more is answered 503 and closed, not queued."""
        if not self._slots.acquire(blocking=False):
            try:
                request.sendall(b"HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
                request.shutdown(socket.SHUT_WR)
                # read what the client sent (briefly): closing over unread bytes would reset the
                # connection, and the client might lose the answer
                request.settimeout(REFUSAL_LINGER_S)
                while request.recv(65536):
                    pass
            except OSError:
                pass
            self.shutdown_request(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._slots.release()

    def host_allowed(self, asked: str) -> bool:
        """Whether a request's Host names this viewer: a loopback name, an allowed name or an IP
        address (DNS rebinding needs a name of the attacker's), with this server's port."""
        port = self.server_address[1]
        name, sep, asked_port = asked.lower().rpartition(":")
        if not sep or asked_port != str(port) or not name:
            return False
        if name in self.allowed_hosts:
            return True
        try:
            ipaddress.ip_address(name[1:-1] if name.startswith("[") and name.endswith("]") else name)
            return True
        except ValueError:
            return False

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A browser that closed a connection mid-answer is normal; anything else is logged."""
        _log.debug("request from %s failed", client_address, exc_info=True)

    @property
    def url(self) -> str:
        host, port = self.server_address[:2]
        return f"http://{host.decode() if isinstance(host, bytes) else host}:{port}/"


class _Handler(BaseHTTPRequestHandler):
    server: ViewerServer
    protocol_version = "HTTP/1.1"
    timeout = CONNECTION_TIMEOUT_S  # the socket's: a half-sent request or an idle connection ends
    _set_cookie: str | None = None

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - the base class's name
        _log.debug("%s %s", self.address_string(), format % args)

    def _send(self, body: bytes, ctype: str, status: int = 200, headers: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        for k, v in (headers or {}).items():
            self.send_header(k, v)
        if self._set_cookie:
            self.send_header("Set-Cookie", self._set_cookie)
        self.end_headers()
        self.wfile.write(body)

    def _json(self, doc: Any, status: int = 200) -> None:
        self._send(json.dumps(doc).encode(), "application/json", status)

    def _foreign_host(self) -> bool:
        """A request whose Host is not one of this viewer's names (DNS rebinding: another site's
        name pointed at this address) is refused 421, so no other site can read the camera through a
        browser; without the viewer's token (if it has one) a request is refused 401."""
        asked = self.headers.get("Host", "")
        if not self.server.host_allowed(asked):
            self._json({"error": f"Host {asked!r} is not this viewer's address (see --allow-host)"},
                       HTTPStatus.MISDIRECTED_REQUEST)
            return True
        token = self.server.token
        if token is None or self._token_given(token):
            return False
        self._json({"error": "this viewer needs its token: open the address it printed (…?token=…)"},
                   HTTPStatus.UNAUTHORIZED)
        return True

    def _token_given(self, token: str) -> bool:
        """Whether the request carries ``token``: in the query (then the page's cookie is set with the
        answer), as its cookie, or as a bearer token."""
        query = parse_qs(urlsplit(self.path).query).get("token", [""])[0]
        cookies = SimpleCookie(self.headers.get("Cookie", ""))
        cookie = cookies[TOKEN_COOKIE].value if TOKEN_COOKIE in cookies else ""
        bearer = self.headers.get("Authorization", "").removeprefix("Bearer ")
        if hmac.compare_digest(query.encode(), token.encode()):
            self._set_cookie = f"{TOKEN_COOKIE}={token}; Path=/; HttpOnly; SameSite=Strict"
            return True
        return any(hmac.compare_digest(v.encode(), token.encode()) for v in (cookie, bearer))

    def do_GET(self) -> None:  # noqa: N802 - http.server's name
        if self._foreign_host():
            return
        url = urlsplit(self.path)
        query = {k: v[0] for k, v in parse_qs(url.query).items()}
        session = self.server.session
        try:
            if isinstance(session, GroupViewerSession):
                self._group_get(session, url.path, query)
            else:
                self._camera_get(session, url.path, query)
        except (KeyError, ValueError) as exc:
            self._json({"error": f"bad request: {exc}"}, HTTPStatus.BAD_REQUEST)
        except stereocam.StereoCamError as exc:
            self._json({"error": str(exc)}, HTTPStatus.BAD_GATEWAY)

    def _static(self, pages: dict[str, tuple[str, str]], path: str) -> bool:
        if path not in pages:
            return False
        name, ctype = pages[path]
        self._send((resources.files(__package__) / "static" / name).read_bytes(), ctype)
        return True

    def _camera_get(self, session: ViewerSession, path: str, query: dict[str, str]) -> None:
        if self._static(STATIC, path):
            return
        if path == "/api/state":
            self._json(session.state())
        elif path == "/api/frame":
            frame = session.newest(int(query.get("after", -1)), wait=1.0)
            self._json(None if frame is None else session.frame_meta(frame))
        elif path.startswith("/image/") and path.endswith(".jpg"):
            got = session.jpeg(path[len("/image/"):-4])
            if got is None:
                self._json({"error": "no such image in the newest frame"}, HTTPStatus.NOT_FOUND)
            else:
                self._send(got[1], "image/jpeg", headers={"X-Sequence": str(got[0]),
                                                          "X-Stale": "1" if session.stale else "0"})
        elif path == "/api/point":
            self._json(session.point(int(query["x"]), int(query["y"])))
        elif path == "/api/points.bin":
            self._cloud(session, int(query.get("step", 2)), query.get("colour", "depth"))
        elif path.startswith("/snapshot/") and path[len("/snapshot/"):] in SNAPSHOTS:
            self._snapshot(session, path[len("/snapshot/"):], query.get("colour", "left"))
        else:
            self._json({"error": f"no such page {path}"}, HTTPStatus.NOT_FOUND)

    def _group_get(self, session: GroupViewerSession, path: str, query: dict[str, str]) -> None:
        if self._static(GROUP_STATIC, path):
            return
        if path == "/api/group/state":
            self._json(session.state())
        elif path == "/api/group/set":
            s = session.newest(int(query.get("after", -1)), wait=1.0)
            self._json(None if s is None else session.set_meta(s))
        elif path.startswith("/image/") and path.endswith(".jpg") and path.count("/") == 3:
            camera, plane = path[len("/image/"):-4].split("/")
            got = session.jpeg(camera, plane)
            if got is None:
                self._json({"error": f"no {plane} image of {camera} in the newest set"}, HTTPStatus.NOT_FOUND)
            else:
                self._send(got[1], "image/jpeg", headers={"X-Trigger": str(got[0])})
        else:
            self._json({"error": f"no such page {path}"}, HTTPStatus.NOT_FOUND)

    def _snapshot(self, session: ViewerSession, name: str, colour: str) -> None:
        frame = session.newest(wait=0)
        if frame is None:
            self._json({"error": "no frame yet"}, HTTPStatus.NOT_FOUND)
            return
        try:
            body = snapshot(frame, name, colour, session.span(frame) if frame.disparity is not None else (0, 1))
        except MissingSnapshot as exc:
            self._json({"error": f"no {name}: {exc}"}, HTTPStatus.NOT_FOUND)
            return
        self._send(body, MEDIA[name[name.rindex("."):]], headers={
            "Content-Disposition": f'attachment; filename="frame{frame.sequence:06d}_{name}"'})

    def _cloud(self, session: ViewerSession, step: int, colour: str) -> None:
        frame = session.newest(wait=0)
        if frame is None or frame.disparity is None:
            self._json({"error": "the newest frame has no disparity"}, HTTPStatus.NOT_FOUND)
            return
        body = cloud_bytes(*sampled_points(frame, step, colour, session.span(frame)))
        self._send(body, "application/octet-stream", headers={"X-Sequence": str(frame.sequence)})

    def _refuse_action(self) -> bool:
        """Actions change the camera: only the viewer's own page may ask. A request another web page
        makes from the user's browser carries its Origin (or is not JSON, which needs a CORS
        preflight this server never grants); a body over MAX_BODY is not read."""
        origin = self.headers.get("Origin")
        if origin is not None and origin != f"http://{self.headers.get('Host', '')}":
            self._json({"error": f"actions from {origin} are refused"}, HTTPStatus.FORBIDDEN)
        elif not self.headers.get("Content-Type", "").startswith("application/json"):
            self._json({"error": "actions take a JSON body (Content-Type: application/json)"},
                       HTTPStatus.UNSUPPORTED_MEDIA_TYPE)
        elif not 0 <= int(self.headers.get("Content-Length", 0) or 0) <= MAX_BODY:
            self._json({"error": f"body over {MAX_BODY} bytes"}, HTTPStatus.REQUEST_ENTITY_TOO_LARGE)
        else:
            return False
        self.close_connection = True  # the body, if any, is not read
        return True

    def _body(self) -> dict[str, Any]:
        """The request's JSON object (empty body: {}); ValueError saying what is wrong with it."""
        if self.headers.get("Transfer-Encoding") is not None:
            self.close_connection = True  # its body is not read
            raise ValueError("a body must come with a Content-Length (Transfer-Encoding is not accepted)")
        data = self.rfile.read(int(self.headers.get("Content-Length", 0) or 0))
        if not data:
            return {}
        try:
            body = json.loads(data, parse_constant=_no_constant)
        except RecursionError:
            raise ValueError("the JSON body is nested too deeply") from None
        except UnicodeDecodeError as exc:
            raise ValueError(f"the body is not UTF-8 ({exc.reason})") from None
        if not isinstance(body, dict):
            raise ValueError(f"the body must be a JSON object, not {type(body).__name__}")
        return body

    def _group_post(self, session: GroupViewerSession, path: str, body: dict[str, Any]) -> None:
        try:
            if path == "/api/group/config":
                self._json({"config": session.configure(_settings(body))})
            elif path == "/api/group/start":
                session.start()
                self._json({"streaming": True})
            elif path == "/api/group/stop":
                session.stop()
                self._json({"streaming": False})
            elif path == "/api/group/trigger":
                self._json(session.one_set())
            else:
                self._json({"error": f"no such action {path}"}, HTTPStatus.NOT_FOUND)
        except stereocam.DeviceError as exc:
            self._json({"error": str(exc), "reason": exc.device_message, "param": exc.param,
                        "config": session.shared_config()}, HTTPStatus.CONFLICT)
        except (stereocam.ConfigError, ValueError, TypeError) as exc:
            self._json({"error": str(exc), "reason": str(exc), "config": session.shared_config()},
                       HTTPStatus.BAD_REQUEST)
        except stereocam.StereoCamError as exc:
            self._json({"error": str(exc), "reason": str(exc)}, HTTPStatus.BAD_GATEWAY)

    @staticmethod
    def _kept(cam: stereocam.Camera) -> dict[str, Any]:
        """The configuration the camera kept after a refusal (the page shows it, not the refused value)."""
        try:
            return {"config": cam.config()}
        except stereocam.StereoCamError:
            return {}

    def do_POST(self) -> None:  # noqa: N802 - http.server's name
        session = self.server.session
        try:
            if self._foreign_host() or self._refuse_action():
                return
        except ValueError:
            self._json({"error": "bad Content-Length"}, HTTPStatus.BAD_REQUEST)
            self.close_connection = True
            return
        path = urlsplit(self.path).path
        try:
            body = self._body()
        except ValueError as exc:
            self._json({"error": f"bad request: {exc}", "reason": str(exc)}, HTTPStatus.BAD_REQUEST)
            return
        if isinstance(session, GroupViewerSession):
            self._group_post(session, path, body)
            return
        cam = session.cam
        try:
            if path == "/api/config":
                self._json({"config": cam.configure(**_settings(body))})
            elif path == "/api/config/reset":
                self._json({"config": session.reset()})
            elif path == "/api/preset/save":
                self._json(session.save_preset(body.get("name")))
            elif path == "/api/preset/load":
                self._json(session.load_preset(body.get("name")))
            elif path == "/api/range":
                self._json({"span": session.set_span(body.get("near_m"), body.get("far_m"))})
            elif path == "/api/start":
                cam.start()
                self._json({"streaming": True})
            elif path == "/api/stop":
                cam.stop()
                self._json({"streaming": False})
            elif path == "/api/trigger":
                self._json({"trigger_id": cam.trigger()})
            elif path == "/api/record/start":
                self._json({"recording": session.start_recording()})
            elif path == "/api/record/stop":
                self._json({"recording": session.stop_recording()})
            else:
                self._json({"error": f"no such action {path}"}, HTTPStatus.NOT_FOUND)
        except stereocam.DeviceError as exc:
            self._json({"error": str(exc), "reason": exc.device_message, "param": exc.param,
                        "code": getattr(exc.code, "name", exc.code), **self._kept(cam)}, HTTPStatus.CONFLICT)
        except (stereocam.ConfigError, RecordingError, ValueError, TypeError, OSError) as exc:
            self._json({"error": str(exc), "reason": str(exc), **self._kept(cam)}, HTTPStatus.BAD_REQUEST)
        except stereocam.StereoCamError as exc:
            self._json({"error": str(exc), "reason": str(exc)}, HTTPStatus.BAD_GATEWAY)
