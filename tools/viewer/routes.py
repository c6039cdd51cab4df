"""What each viewer endpoint answers (the list is server.py's docstring): a session's pages, state,
images and actions as an Answer. The HTTP around them (Host and token checks, connection limits,
reading a body) is server.py's."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from http import HTTPStatus
from importlib import resources
from typing import Any

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


@dataclass(frozen=True)
class Answer:
    """An HTTP answer: its body, content type, status and extra headers."""

    body: bytes
    ctype: str
    status: int = HTTPStatus.OK
    headers: dict[str, str] = field(default_factory=dict)


def json_answer(doc: Any, status: int = HTTPStatus.OK) -> Answer:
    return Answer(json.dumps(doc).encode(), "application/json", status)


def _not_found(what: str) -> Answer:
    return json_answer({"error": what}, HTTPStatus.NOT_FOUND)


def _static(pages: dict[str, tuple[str, str]], path: str) -> Answer | None:
    if path not in pages:
        return None
    name, ctype = pages[path]
    return Answer((resources.files(__package__) / "static" / name).read_bytes(), ctype)


def camera_get(session: ViewerSession, path: str, query: dict[str, str]) -> Answer:
    """A GET of a one-camera viewer; KeyError or ValueError for a bad query."""
    if (page := _static(STATIC, path)) is not None:
        return page
    if path == "/api/state":
        return json_answer(session.state())
    if path == "/api/frame":
        frame = session.newest(int(query.get("after", -1)), wait=1.0)
        return json_answer(None if frame is None else session.frame_meta(frame))
    if path.startswith("/image/") and path.endswith(".jpg"):
        got = session.jpeg(path[len("/image/"):-4])
        if got is None:
            return _not_found("no such image in the newest frame")
        return Answer(got[1], "image/jpeg",
                      headers={"X-Sequence": str(got[0]), "X-Stale": "1" if session.stale else "0"})
    if path == "/api/point":
        return json_answer(session.point(int(query["x"]), int(query["y"])))
    if path == "/api/points.bin":
        return _cloud(session, int(query.get("step", 2)), query.get("colour", "depth"))
    if path.startswith("/snapshot/") and path[len("/snapshot/"):] in SNAPSHOTS:
        return _snapshot(session, path[len("/snapshot/"):], query.get("colour", "left"))
    return _not_found(f"no such page {path}")


def group_get(session: GroupViewerSession, path: str, query: dict[str, str]) -> Answer:
    """A GET of a camera group's viewer; KeyError or ValueError for a bad query."""
    if (page := _static(GROUP_STATIC, path)) is not None:
        return page
    if path == "/api/group/state":
        return json_answer(session.state())
    if path == "/api/group/set":
        s = session.newest(int(query.get("after", -1)), wait=1.0)
        return json_answer(None if s is None else session.set_meta(s))
    if path.startswith("/image/") and path.endswith(".jpg") and path.count("/") == 3:
        camera, plane = path[len("/image/"):-4].split("/")
        got = session.jpeg(camera, plane)
        if got is None:
            return _not_found(f"no {plane} image of {camera} in the newest set")
        return Answer(got[1], "image/jpeg", headers={"X-Trigger": str(got[0])})
    return _not_found(f"no such page {path}")


def _snapshot(session: ViewerSession, name: str, colour: str) -> Answer:
    frame = session.newest(wait=0)
    if frame is None:
        return _not_found("no frame yet")
    try:
        body = snapshot(frame, name, colour, session.span(frame) if frame.disparity is not None else (0, 1))
    except MissingSnapshot as exc:
        return _not_found(f"no {name}: {exc}")
    return Answer(body, MEDIA[name[name.rindex("."):]], headers={
        "Content-Disposition": f'attachment; filename="frame{frame.sequence:06d}_{name}"'})


def _cloud(session: ViewerSession, step: int, colour: str) -> Answer:
    frame = session.newest(wait=0)
    if frame is None or frame.disparity is None:
        return _not_found("the newest frame has no disparity")
    body = cloud_bytes(*sampled_points(frame, step, colour, session.span(frame)))
    return Answer(body, "application/octet-stream", headers={"X-Sequence": str(frame.sequence)})


def _settings(body: dict[str, Any]) -> dict[str, int]:
    """``body`` as parameter settings: every value an integer (not true, 320.7 or 1e400)."""
    for name, value in body.items():
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"{name}: {json.dumps(value)[:40]} is not an integer")
    return body


def _kept(cam: stereocam.Camera) -> dict[str, Any]:
    """The configuration the camera kept after a refusal (the page shows it, not the refused value)."""
    try:
        return {"config": cam.config()}
    except stereocam.StereoCamError:
        return {}


def camera_post(session: ViewerSession, path: str, body: dict[str, Any]) -> Answer:
    """An action on a one-camera viewer; a refusal answers with the reason and what the camera kept."""
    cam = session.cam
    try:
        if path == "/api/config":
            return json_answer({"config": cam.configure(**_settings(body))})
        if path == "/api/config/reset":
            return json_answer({"config": session.reset()})
        if path == "/api/preset/save":
            return json_answer(session.save_preset(body.get("name")))
        if path == "/api/preset/load":
            return json_answer(session.load_preset(body.get("name")))
        if path == "/api/range":
            return json_answer({"span": session.set_span(body.get("near_m"), body.get("far_m"))})
        if path == "/api/start":
            cam.start()
            return json_answer({"streaming": True})
        if path == "/api/stop":
            cam.stop()
            return json_answer({"streaming": False})
        if path == "/api/trigger":
            return json_answer({"trigger_id": cam.trigger()})
        if path == "/api/record/start":
            return json_answer({"recording": session.start_recording()})
        if path == "/api/record/stop":
            return json_answer({"recording": session.stop_recording()})
        return _not_found(f"no such action {path}")
    except stereocam.DeviceError as exc:
        return json_answer({"error": str(exc), "reason": exc.device_message, "param": exc.param,
                            "code": getattr(exc.code, "name", exc.code), **_kept(cam)}, HTTPStatus.CONFLICT)
    except (stereocam.ConfigError, RecordingError, ValueError, TypeError, OSError) as exc:
        return json_answer({"error": str(exc), "reason": str(exc), **_kept(cam)}, HTTPStatus.BAD_REQUEST)
    except stereocam.StereoCamError as exc:
        return json_answer({"error": str(exc), "reason": str(exc)}, HTTPStatus.BAD_GATEWAY)


def group_post(session: GroupViewerSession, path: str, body: dict[str, Any]) -> Answer:
    """An action on every head of a group; a refusal names the head and changes none."""
    try:
        if path == "/api/group/config":
            return json_answer({"config": session.configure(_settings(body))})
        if path == "/api/group/start":
            session.start()
            return json_answer({"streaming": True})
        if path == "/api/group/stop":
            session.stop()
            return json_answer({"streaming": False})
        if path == "/api/group/trigger":
            return json_answer(session.one_set())
        return _not_found(f"no such action {path}")
    except stereocam.DeviceError as exc:
        return json_answer({"error": str(exc), "reason": exc.device_message, "param": exc.param,
                            "config": session.shared_config()}, HTTPStatus.CONFLICT)
    except (stereocam.ConfigError, ValueError, TypeError) as exc:
        return json_answer({"error": str(exc), "reason": str(exc), "config": session.shared_config()},
                           HTTPStatus.BAD_REQUEST)
    except stereocam.StereoCamError as exc:
        return json_answer({"error": str(exc), "reason": str(exc)}, HTTPStatus.BAD_GATEWAY)
