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

Here: the HTTP (the Host and token checks, connection limits, reading a POST body); what each
endpoint answers is routes.py's.
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
from typing import Any, Iterable
from urllib.parse import parse_qs, urlsplit

import stereocam
from .group_session import GroupViewerSession
from .routes import Answer, camera_get, camera_post, group_get, group_post, json_answer
from .session import ViewerSession

MAX_BODY = 64 * 1024  # bytes of a POST body: a configuration is a few hundred
_log = logging.getLogger(__name__)


LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")
TOKEN_COOKIE = "stereocam_viewer_token"
TOKEN_CHARS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-._~")
"""What a token may hold: it travels unquoted in the printed address's query and in a cookie, where
a space, ';', '&', '%' or '=' would cut or change it (secrets.token_urlsafe's alphabet is within)."""


def token_problem(token: str) -> str | None:
    """Why ``token`` cannot work (None: it can)."""
    if not token:
        return "must not be empty"
    bad = sorted({c for c in token if c not in TOKEN_CHARS})
    if bad:
        return (f"may hold only letters, digits, '-', '.', '_' and '~' (it goes into the address and a "
                f"cookie as it is), got {''.join(bad)!r}")
    return None
CONNECTION_TIMEOUT_S = 15.0  # a connection silent this long (half-sent request, idle keep-alive) is closed
MAX_CONNECTIONS = 32  # connections served at once; more are answered 503 and closed
REFUSAL_LINGER_S = 0.2  # how long a refused connection's request is read before it is closed


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} is not a number a setting can take")


class ViewerServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, session: ViewerSession | GroupViewerSession, host: str = "127.0.0.1", port: int = 0,
                 allowed_hosts: Iterable[str] = (), token: str | None = None,
                 max_connections: int = MAX_CONNECTIONS):
        """``allowed_hosts``: host names (besides loopback names and IP addresses) a request's Host
        may carry, for a viewer reachable from a network; ``token``: if given, every request must
        carry it (``?token=`` once, then the cookie the page gets; or ``Authorization: Bearer``)."""
        why = None if token is None else token_problem(token)
        if why:
            raise ValueError(f"token {why}")
        self.session = session
        self.allowed_hosts = {h.lower() for h in (*LOOPBACK_NAMES, *allowed_hosts)}
        self.token = token
        self._slots = threading.BoundedSemaphore(max_connections)
        self._holders: set[Any] = set()  # requests holding a slot: each gives it back exactly once
        self._holders_lock = threading.Lock()
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
        with self._holders_lock:
            self._holders.add(request)
        try:
            super().process_request(request, client_address)
        except BaseException:
            # a thread that could not start, or a Ctrl-C/SIGTERM while it started (it may already
            # have served the request and given the slot back): the slot is given back once, and
            # the interrupt goes on to serve_forever's caller instead of dying in handle_error
            self._give_back(request)
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        try:
            super().process_request_thread(request, client_address)
        finally:
            self._give_back(request)

    def _give_back(self, request: Any) -> None:
        with self._holders_lock:
            if request not in self._holders:
                return
            self._holders.discard(request)
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

    def _send(self, answer: Answer) -> None:
        self.send_response(answer.status)
        self.send_header("Content-Type", answer.ctype)
        self.send_header("Content-Length", str(len(answer.body)))
        self.send_header("Cache-Control", "no-store")
        for k, v in answer.headers.items():
            self.send_header(k, v)
        if self._set_cookie:
            self.send_header("Set-Cookie", self._set_cookie)
        self.end_headers()
        self.wfile.write(answer.body)

    def _json(self, doc: Any, status: int = HTTPStatus.OK) -> None:
        self._send(json_answer(doc, status))

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
                answer = group_get(session, url.path, query)
            else:
                answer = camera_get(session, url.path, query)
        except (KeyError, ValueError) as exc:
            answer = json_answer({"error": f"bad request: {exc}"}, HTTPStatus.BAD_REQUEST)
        except stereocam.StereoCamError as exc:
            answer = json_answer({"error": str(exc)}, HTTPStatus.BAD_GATEWAY)
        self._send(answer)

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
            self._send(group_post(session, path, body))
        else:
            self._send(camera_post(session, path, body))
