"""stereocam view in a real headless browser (the distribution's Chromium, over DevTools)."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

import stereocam
from stereocam.recording.reader import Recording
from stereocam.tools.viewer.server import ViewerServer
from stereocam.tools.viewer.session import ViewerSession
from tests.support.browser import Chromium, find_chromium
from tests.support.device import SMALL
from tests.support.hangs import returns_within, terminated
from tests.support.waiting import wait_until

CHROMIUM = find_chromium()
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="no Chromium on this machine (apt-get install chromium; "
                                                            ".ci/run installs it)")


@pytest.fixture
def viewer(tmp_path):
    cam = stereocam.open("sim://?seed=6", timeout=2.0)
    cam.configure(**SMALL, fps=10)
    server = ViewerServer(ViewerSession(cam, tmp_path / "recordings"))
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    thread.start()
    cam.start()
    yield server
    server.shutdown()
    server.server_close()
    server.session.close()
    cam.close()


def _get(url: str) -> tuple[dict[str, str], bytes]:
    with urllib.request.urlopen(url, timeout=30) as r:
        return dict(r.headers), r.read()


def _frames_pass(url: str, after: int, count: int) -> None:
    """Wait until the viewer at ``url`` has had ``count`` frames newer than sequence ``after``."""
    wait_until(lambda: (json.loads(_get(url + f"api/frame?after={after}")[1]) or {}).get("sequence", -1)
               >= after + count, timeout=20, what=f"{count} frames after {after}")


def _recorded(url: str, frames: int) -> None:
    """Wait until the recording of the viewer at ``url`` holds ``frames`` frames."""
    wait_until(lambda: (json.loads(_get(url + "api/state")[1])["recording"] or {}).get("frames", 0) >= frames,
               timeout=20, what=f"{frames} frames recorded")


def test_images_are_always_the_newest_frame(viewer):
    first = json.loads(_get(viewer.url + "api/frame")[1])
    _frames_pass(viewer.url, first["sequence"], 10)  # nobody looks: more frames than a queue holds are replaced
    headers, body = _get(viewer.url + "image/left.jpg")
    assert int(headers["X-Sequence"]) > first["sequence"]
    img = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (240, 320)
    assert viewer.session.skipped > 0  # the viewer's slot held one frame at a time, never a backlog
    assert viewer.session.cam.stats["queue_overflow"] == 0  # and no unread get_frame queue counting drops


def _post(url: str, doc: dict | None = None, headers: dict | None = None, body: bytes | None = None
          ) -> tuple[int, dict]:
    req = urllib.request.Request(url, data=json.dumps(doc or {}).encode() if body is None else body, method="POST",
                                 headers={"Content-Type": "application/json", **(headers or {})})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


def test_record_button_records_every_frame_while_the_page_shows_the_newest(viewer):
    (viewer.session.record_dir).mkdir()
    status, doc = _post(viewer.url + "api/record/start")
    assert status == 200 and not doc["recording"]["done"]
    assert _post(viewer.url + "api/record/start")[0] == 400  # one recording at a time, said so
    _recorded(viewer.url, 5)
    status, doc = _post(viewer.url + "api/record/stop")
    rec = doc["recording"]
    assert status == 200 and rec["done"] and rec["frames"] >= 5 and rec["recorder_dropped"] == 0
    assert _post(viewer.url + "api/record/stop")[0] == 400
    with Recording(rec["path"]) as r:  # a finished file: summary, index, every frame in order
        assert len(r) == rec["frames"] and r.device["serial"] == "SIM00006"
        sequences = [c.info.sequence for c in r.captures()]
    assert sequences == sorted(set(sequences))
    dropped = viewer.session.cam.status().counters["frames_dropped"]
    assert sequences[-1] - sequences[0] + 1 - len(sequences) <= dropped  # the recorder skipped none the device sent


def test_actions_from_another_web_page_are_refused_and_change_nothing(viewer):
    """A page on another origin, a form post (no preflight) or an oversized body cannot act."""
    cam = viewer.session.cam
    before = cam.config()
    code, doc = _post(viewer.url + "api/config", {"gain": 90}, headers={"Origin": "http://evil.example"})
    assert code == 403 and "evil.example" in doc["error"]
    code, _ = _post(viewer.url + "api/config", body=b"gain=90",
                    headers={"Content-Type": "application/x-www-form-urlencoded"})
    assert code == 415
    code, _ = _post(viewer.url + "api/stop", body=b"{" + b" " * (100 << 10) + b"}")  # over 64 KiB
    assert code == 413
    assert cam.config() == before and cam.streaming
    port = viewer.url.rstrip("/").rsplit(":", 1)[1]
    code, _ = _post(viewer.url + "api/config", {"gain": 90}, headers={"Host": f"evil.example:{port}"})
    assert code == 421  # DNS rebinding: another site's name pointed at this machine
    req = urllib.request.Request(viewer.url + "image/left.jpg", headers={"Host": f"evil.example:{port}"})
    with pytest.raises(urllib.error.HTTPError) as info:
        urllib.request.urlopen(req, timeout=30)
    assert info.value.code == 421  # nor may it read the images
    assert cam.config() == before
    host = viewer.url.split("//")[1].rstrip("/")
    code, doc = _post(viewer.url + "api/config", {"gain": 90}, headers={"Origin": f"http://{host}"})
    assert code == 200 and doc["config"]["gain"] == 90  # the viewer's own page


def test_recording_into_a_folder_that_is_not_there_is_refused_with_the_reason(viewer):
    status, doc = _post(viewer.url + "api/record/start")  # record_dir was never made
    assert status == 400 and "recordings" in doc["reason"]
    assert json.loads(_get(viewer.url + "api/state")[1])["recording"] is None


@needs_browser
def test_viewer_page_in_a_headless_browser(viewer, tmp_path):
    browser = Chromium(CHROMIUM)
    try:
        page = browser.page(viewer.url)
        browser.wait_for(page, "document.getElementById('disparity').naturalWidth > 0 && "
                               "document.getElementById('left').naturalWidth > 0")
        seq1 = int(browser.evaluate(page, "document.getElementById('sequence').textContent"))
        shot1 = browser.screenshot(page)
        browser.wait_for(page, f"Number(document.getElementById('sequence').textContent) > {seq1 + 2}")
        shot2 = browser.screenshot(page)
        a, b = (cv2.imdecode(np.frombuffer(s, np.uint8), cv2.IMREAD_COLOR) for s in (shot1, shot2))
        assert a.shape == b.shape and np.abs(a.astype(int) - b.astype(int)).mean() > 0.05, "live image did not change"

        ticks = browser.evaluate(page, "[...document.querySelectorAll('#ticks span')].map(s => s.textContent)")
        assert ticks and all(t.endswith(" m") for t in ticks)
        browser.wait_for(page, "document.getElementById('param-block_size') !== null")
        browser.evaluate(page, "(() => { const i = document.getElementById('in-block_size'); i.value = 10; "
                               "i.dispatchEvent(new Event('change')); })()")
        reason = browser.wait_for(page, "document.querySelector('#param-block_size .reason').textContent")
        assert "refused" in reason and "must be odd" in reason
        assert viewer.session.cam.config()["block_size"] == SMALL["block_size"]

        browser.evaluate(page, "(() => { const i = document.getElementById('in-exposure_us'); i.value = 2500; "
                               "i.dispatchEvent(new Event('change')); })()")
        browser.wait_for(page, "document.querySelector('#param-exposure_us .reason').textContent.includes('= 2500')")
        assert viewer.session.cam.config()["exposure_us"] == 2500

        box = browser.evaluate(page, "JSON.stringify(document.getElementById('disparity').getBoundingClientRect())")
        box = json.loads(box)
        browser.send("Input.dispatchMouseEvent", {"type": "mouseMoved", "x": box["x"] + box["width"] / 2,
                                                  "y": box["y"] + box["height"] / 2}, page)
        browser.wait_for(page, "document.getElementById('cursor').textContent.includes('(')")
        cursor = browser.evaluate(page, "document.getElementById('cursor').textContent")
        assert "depth" in cursor or "no depth" in cursor
        viewer.session.record_dir.mkdir()
        browser.evaluate(page, "document.getElementById('record').click()")
        browser.wait_for(page, "document.getElementById('record').textContent === 'Stop recording'")
        _recorded(viewer.url, 3)
        browser.evaluate(page, "document.getElementById('record').click()")
        saved = browser.wait_for(page, "document.getElementById('recording').textContent.startsWith('saved') && "
                                       "document.getElementById('recording').textContent")
        assert ".mcap" in saved and list(viewer.session.record_dir.glob("*.mcap"))
        browser.wait_for(page, "[...document.images].every(i => i.complete)")  # the picture, fully drawn
        out = Path(os.environ.get("STEREOCAM_SCREENSHOT", tmp_path / "viewer.png"))
        out.write_bytes(browser.screenshot(page))
    finally:
        browser.close()


def test_a_record_dir_that_cannot_be_written_stops_the_viewer_at_once():
    """Checked by a write when the viewer starts, not when Record is pressed minutes later."""
    r = subprocess.run([sys.executable, "-m", "stereocam.tools.cli", "view", "sim://?seed=9", "--no-browser",
                        "--record-dir", "/proc/stereocam-nope"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--record-dir" in r.stderr and "cannot write into directory" in r.stderr
    assert "Traceback" not in r.stderr and not r.stdout


def test_view_command_prints_its_address_first_and_restores_the_camera(tmp_path):
    from stereocam.device_sim.process import ServedSimulator

    with ServedSimulator("tcp:127.0.0.1:0", seed=8) as sim:
        proc = subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", "view", sim.url, "--no-browser"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            url = proc.stdout.readline().strip()
            assert url.startswith("http://127.0.0.1:")
            code, doc = _post(url + "api/config", {"gain": 300})
            assert code == 409 and "gain=300" in doc["reason"]
            code, doc = _post(url + "api/config", {"gain": 40})
            assert code == 200 and doc["config"]["gain"] == 40
        finally:
            assert (rc := terminated(proc)) == 0, (rc, proc.stderr.read())
        with stereocam.open(sim.url, timeout=2.0) as cam:
            assert cam.config()["gain"] == 0  # put back as found


@pytest.fixture
def group_viewer():
    """Three in-process heads on one trigger line driven by the first one (the group's master), viewed as a group."""
    from stereocam.device_sim import SimulatedCamera, TriggerLine
    from stereocam.tools.viewer.group_session import GroupViewerSession

    line = TriggerLine()
    sims = [SimulatedCamera(serial=f"VIEW{i}", seed=30 + i, trigger_line=line) for i in range(3)]
    group = stereocam.CameraGroup([f"sim://?serial={s.serial}" for s in sims], settle=0.3, timeout=5.0,
                                  config=dict(width=160, height=120, num_disparities=16, block_size=9, fps=10))
    group.open()
    server = ViewerServer(GroupViewerSession(group))
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
    thread.start()
    yield server, sims
    server.shutdown()
    server.server_close()
    server.session.close()
    group.close()
    for s in sims:
        s.close()


def test_group_view_serves_the_newest_matched_set_and_names_a_missed_head(group_viewer):
    server, sims = group_viewer
    first = json.loads(_get(server.url + "api/group/set")[1])
    assert set(first["frames"]) == {"VIEW0", "VIEW1", "VIEW2"} and first["skew_us"] < 1000
    headers, body = _get(server.url + "image/VIEW2/disparity.jpg")
    assert int(headers["X-Trigger"]) >= first["trigger_id"]
    assert cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR).shape == (120, 160, 3)
    sims[1].trigger_input.miss_next = 1  # this head misses the next edge
    state = wait_until(lambda: (s := json.loads(_get(server.url + "api/group/state")[1]))["missed"] and s, 20,
                       "a missed set reported")
    assert state["missed"][0]["missing"] == ["VIEW1"] and state["sets"]["incomplete"] >= 1
    assert [c["name"] for c in state["cameras"]] == ["VIEW0", "VIEW1", "VIEW2"]
    assert all(0 < c["clock_sigma_us"] < 1000 for c in state["cameras"])
    later = json.loads(_get(server.url + f"api/group/set?after={first['trigger_id']}")[1])
    assert later["trigger_id"] > first["trigger_id"]


@needs_browser
def test_group_view_page_in_a_headless_browser(group_viewer, tmp_path):
    server, _ = group_viewer
    browser = Chromium(CHROMIUM)
    try:
        page = browser.page(server.url)
        browser.wait_for(page, "document.querySelectorAll('img.head').length === 6 && "
                               "[...document.querySelectorAll('img.head')].every(i => i.naturalWidth > 0)")
        t1 = int(browser.evaluate(page, "document.getElementById('trigger-id').textContent"))
        browser.wait_for(page, f"Number(document.getElementById('trigger-id').textContent) > {t1 + 2}")
        skew = float(browser.evaluate(page, "document.getElementById('skew').textContent"))
        assert 0 <= skew < 1000
        identity = browser.wait_for(page, "document.getElementById('identity').textContent.includes('clock map') && "
                                          "document.getElementById('identity').textContent")
        assert all(f"VIEW{i}" in identity for i in range(3))
        out = Path(os.environ.get("STEREOCAM_GROUP_SCREENSHOT", tmp_path / "group.png"))
        out.write_bytes(browser.screenshot(page))
    finally:
        browser.close()


def _complete_set(url: str) -> dict | None:
    """The newest matched set of the group viewer at ``url`` if every head is in it (a head still
    starting, or one that missed an edge under load, leaves a set incomplete: wait for the next)."""
    s = json.loads(_get(url + "api/group/set")[1])
    return s if s and s["complete"] else None


def test_view_command_with_several_urls_shows_a_group_and_puts_each_head_back():
    from stereocam.device_sim.process import ServedSimulator

    line = f"view-{os.getpid()}"
    servers = [ServedSimulator("tcp:127.0.0.1:0", seed=40 + i, extra=["--trigger-line", line]) for i in range(2)]
    try:
        proc = subprocess.Popen([sys.executable, "-m", "stereocam.tools.cli", "view", *(s.url for s in servers),
                                 "--no-browser", "--master", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            url = proc.stdout.readline().strip()
            assert url.startswith("http://127.0.0.1:"), proc.stderr.read()
            s = wait_until(lambda: _complete_set(url), timeout=30, what="a complete matched set")
            assert set(s["frames"]) == {"SIM00040", "SIM00041"} and s["complete"]
        finally:
            assert (rc := terminated(proc)) == 0, (rc, proc.stderr.read())
        for srv in servers:
            with stereocam.open(srv.url, timeout=2.0) as cam:
                config = cam.config()
                assert config["trigger_mode"] == 0 and config["trigger_output"] == 0  # as found
    finally:
        for srv in servers:
            srv.stop()


def test_a_device_chosen_serial_cannot_put_a_recording_outside_its_folder(tmp_path):
    from stereocam.device_sim import SimulatedCamera

    sim = SimulatedCamera(serial="../../escape/x", seed=9)
    cam = stereocam.open(f"sim://?serial={sim.serial}", timeout=2.0)
    session = ViewerSession(cam, tmp_path / "rec")
    try:
        (tmp_path / "rec").mkdir()
        path = Path(session.start_recording()["path"])
        assert path.parent == tmp_path / "rec" and "/" not in path.name and path.name.startswith("view_.._.._escape_x_")
        session.stop_recording()
    finally:
        session.close()
        cam.close()
        sim.close()


# -- issue 22 items 5 and 12: a viewer on a network, hostile bodies and connections ----------------
def _raw(server: ViewerServer, request: bytes, timeout: float = 10) -> bytes:
    """``request`` sent as it is; the whole answer (up to the server closing or ``timeout``)."""
    import socket

    with socket.create_connection(server.server_address[:2], timeout=timeout) as s:
        s.sendall(request)
        s.shutdown(socket.SHUT_WR)
        chunks = []
        while chunk := s.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


def _post_raw(server: ViewerServer, body: bytes, extra: str = "") -> bytes:
    port = server.server_address[1]
    head = (f"POST /api/config HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n{extra}\r\n")
    return _raw(server, head.encode() + body)


@pytest.mark.parametrize("body", [b"[1, 2]", b'"fps"', b"null", b"12", b'{"fps": Infinity}', b'{"fps": NaN}',
                                  b'{"fps": 1e400}', b"[" * 30000 + b"]" * 30000, b'{"fps": true}',
                                  b'{"width": 320.7}', b'{"fps": "12"}', b"\xff\xfe"])
def test_a_body_that_is_not_integer_settings_is_answered_400_with_a_reason(viewer, body):
    before = viewer.session.cam.config()
    answer = _post_raw(viewer, body)
    assert answer.startswith(b"HTTP/1.1 400"), answer[:200]
    assert b'"reason"' in answer
    assert viewer.session.cam.config() == before


def test_a_chunked_body_is_refused_not_read_as_empty(viewer):
    before = viewer.session.cam.config()
    port = viewer.server_address[1]
    answer = _raw(viewer, (f"POST /api/config HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nContent-Type: application/json"
                           f"\r\nTransfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
                           f"9\r\n{{\"fps\": 5}}\r\n0\r\n\r\n").encode())
    assert answer.startswith(b"HTTP/1.1 400") and b"Transfer-Encoding" in answer
    assert viewer.session.cam.config() == before


def test_idle_half_sent_connections_time_out_and_are_limited(tmp_path, monkeypatch):
    import socket

    from stereocam.tools.viewer import server as server_module

    monkeypatch.setattr(server_module._Handler, "timeout", 1.0)
    cam = stereocam.open("sim://?seed=6", timeout=2.0)
    server = ViewerServer(ViewerSession(cam, tmp_path), max_connections=4)
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    idle = []
    try:
        for _ in range(4):
            s = socket.create_connection(server.server_address[:2], timeout=10)
            s.sendall(b"POST /api/config HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # and then nothing
            idle.append(s)
        wait_until(lambda: not server._slots._value, 5, "every slot taken by a silent peer")
        assert _raw(server, b"GET /api/state HTTP/1.1\r\n\r\n").startswith(b"HTTP/1.1 503")  # one more: refused
        for s in idle:  # each silent connection is closed by the server after its timeout
            assert returns_within(10, s.recv, 100) == b""
        answer = _raw(server, f"GET /api/frame HTTP/1.1\r\nHost: 127.0.0.1:{server.server_address[1]}\r\n"
                              f"Connection: close\r\n\r\n".encode())
        assert answer.startswith(b"HTTP/1.1 200")  # and the viewer serves again
    finally:
        for s in idle:
            s.close()
        server.shutdown()
        server.server_close()
        server.session.close()
        cam.close()


def test_a_stop_signal_while_a_request_thread_starts_ends_serving(tmp_path, monkeypatch):
    """SIGTERM/Ctrl-C lands in the serving thread while it starts a request's thread, and that
    thread has already answered: the interrupt must reach serve_forever's caller (it was lost,
    turned into "semaphore released too many times", and `stereocam view` never stopped)."""
    cam = stereocam.open("sim://?seed=6", timeout=2.0)
    server = ViewerServer(ViewerSession(cam, tmp_path), max_connections=2)
    server.timeout = 10.0
    url = server.url + "api/state"
    real_start = threading.Thread.start
    answered: list[int] = []
    client = threading.Thread(target=lambda: answered.append(urllib.request.urlopen(url, timeout=30).status))
    client.start()

    def start_serve_then_interrupt(thread: threading.Thread) -> None:
        real_start(thread)
        thread.join()  # the request is served, and its slot given back, before the interrupt
        raise KeyboardInterrupt

    try:
        monkeypatch.setattr(threading.Thread, "start", start_serve_then_interrupt)
        with pytest.raises(KeyboardInterrupt):
            server.handle_request()
        monkeypatch.undo()
        client.join(30)
        assert answered == [200]
        for _ in range(2):  # both slots are free: two silent peers are each given one ...
            threading.Thread(target=server.handle_request, daemon=True).start()
        peers = [socket.create_connection(server.server_address[:2], timeout=10) for _ in range(2)]
        wait_until(lambda: not server._slots._value, 5, "both slots taken")
        for p in peers:
            p.close()
        wait_until(lambda: server._slots._value == 2, 15, "both slots given back")  # ... and no more
    finally:
        monkeypatch.undo()
        server.server_close()
        server.session.close()
        cam.close()


def _network_viewer(tmp_path, **kw) -> ViewerServer:
    cam = stereocam.open("sim://?seed=6", timeout=2.0)
    server = ViewerServer(ViewerSession(cam, tmp_path), host="0.0.0.0", **kw)
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    return server


def _close(server: ViewerServer) -> None:
    server.shutdown()
    server.server_close()
    server.session.close()
    server.session.cam.close()


def test_a_viewer_on_all_addresses_answers_only_its_own_names(tmp_path):
    server = _network_viewer(tmp_path, allowed_hosts=["camera-bench.lan"])
    port = server.server_address[1]
    try:
        def get(host: str, path: str = "/api/state", extra: str = "") -> bytes:
            return _raw(server, f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n{extra}\r\n".encode())
        for host in (f"evil.example:{port}", "evil.example", f"camera-bench.lan:{port + 1}"):
            assert get(host, extra=f"Origin: http://{host}\r\n").startswith(b"HTTP/1.1 421"), host
            answer = _raw(server, (f"POST /api/start HTTP/1.1\r\nHost: {host}\r\nOrigin: http://{host}\r\n"
                                   f"Content-Type: application/json\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
                                   ).encode())
            assert answer.startswith(b"HTTP/1.1 421"), host
        for host in (f"camera-bench.lan:{port}", f"localhost:{port}", f"192.168.1.20:{port}", f"[fe80::1]:{port}"):
            assert get(host).startswith(b"HTTP/1.1 200"), host
    finally:
        _close(server)


def test_a_token_that_the_address_or_cookie_would_cut_is_refused():
    from stereocam.tools.viewer.server import ViewerServer

    for bad in ("a b", "x;y", "", "é"):
        with pytest.raises(ValueError, match="token"):
            ViewerServer(None, token=bad)  # type: ignore[arg-type]  # refused before the session is used


def test_a_viewer_with_a_token_answers_only_requests_that_carry_it(tmp_path):
    server = _network_viewer(tmp_path, token="s3cret")
    host = f"127.0.0.1:{server.server_address[1]}"
    try:
        def get(path: str, extra: str = "") -> bytes:
            return _raw(server, f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n{extra}\r\n".encode())
        assert get("/api/state").startswith(b"HTTP/1.1 401")
        assert get("/api/state?token=wrong").startswith(b"HTTP/1.1 401")
        page = get("/?token=s3cret")
        assert page.startswith(b"HTTP/1.1 200") and b"Set-Cookie: stereocam_viewer_token=s3cret" in page
        assert get("/api/state", "Cookie: stereocam_viewer_token=s3cret\r\n").startswith(b"HTTP/1.1 200")
        assert get("/api/state", "Authorization: Bearer s3cret\r\n").startswith(b"HTTP/1.1 200")
    finally:
        _close(server)


# -- issue 22 item 13: the camera restarts under the viewer ------------------------------------------
def test_the_viewer_marks_the_last_frame_stale_and_reconnects_after_the_camera_restarts(tmp_path):
    from stereocam.device_sim.process import ServedSimulator

    sim = ServedSimulator("tcp:127.0.0.1:0", seed=44)
    port = sim.url.rstrip("/").rsplit(":", 1)[1]
    cam = stereocam.open(sim.url, timeout=2.0)
    cam.configure(**SMALL, fps=10)
    server = ViewerServer(ViewerSession(cam, tmp_path))
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    cam.start()

    def frame() -> dict:
        return json.loads(_get(server.url + "api/frame")[1])

    def state_ok() -> bool:
        try:
            return not json.loads(_get(server.url + "api/state")[1])["stale"]
        except urllib.error.HTTPError:
            return False

    try:
        wait_until(lambda: frame() is not None, 20, "a frame")
        assert frame()["stale"] is False
        sim.stop()
        wait_until(lambda: frame()["stale"], 20, "the last frame said to be stale")  # the last frame is served, said to be stale
        headers, _ = _get(server.url + "image/left.jpg")
        assert headers["X-Stale"] == "1"
        last = frame()["sequence"]
        sim = ServedSimulator(f"tcp:127.0.0.1:{port}", seed=44)  # the same unit, back on its address
        wait_until(state_ok, 30, "the state answered again")  # reconnected: state answers again
        wait_until(lambda: (f := frame())["stale"] is False and f["sequence"] != last, 30, "live frames")  # and frames are live
        assert json.loads(_get(server.url + "api/state")[1])["config"]["fps"] == 10  # with the viewer's settings
    finally:
        server.shutdown()
        server.server_close()
        server.session.close()
        cam.close()
        sim.stop()


# -- issue 20 item 1: what the page's controls post ------------------------------------------------
def test_a_refusal_answers_the_configuration_the_camera_kept(viewer):
    code, doc = _post(viewer.url + "api/config", {"block_size": 10})
    assert code == 409 and "must be odd" in doc["reason"] and doc["config"]["block_size"] == SMALL["block_size"]
    code, doc = _post(viewer.url + "api/config", {"no_such_setting": 1})
    assert code == 400 and "no_such_setting" in doc["reason"] and doc["config"] == viewer.session.cam.config()


def test_bad_presets_and_ranges_are_refused_with_the_reason(viewer):
    code, doc = _post(viewer.url + "api/preset/save", {"name": "../outside"})
    assert code == 400 and "preset name" in doc["reason"]
    code, doc = _post(viewer.url + "api/preset/load", {"name": "never-saved"})
    assert code == 400 and "no preset 'never-saved'" in doc["reason"]
    code, doc = _post(viewer.url + "api/range", {"near_m": 3, "far_m": 1})
    assert code == 400 and "near" in doc["reason"] and viewer.session.span_m is None
    code, doc = _post(viewer.url + "api/range", {"near_m": 0.5, "far_m": 4})
    assert code == 200 and doc["span"] == {"near_m": 0.5, "far_m": 4.0}
    code, doc = _post(viewer.url + "api/range", {"near_m": None, "far_m": None})
    assert code == 200 and viewer.session.span_m is None


# -- audit: --master and --token values that name no camera or turn the token off -----------------
@pytest.mark.parametrize("argv, words", [
    (["sim://?seed=9", "--master", "5"], "expected 0..0 (a camera's place among the URLs) or 'none', got '5'"),
    (["sim://?seed=9", "--master", "abc"], "got 'abc'"),
    (["sim://?seed=9", "--master", "-1"], "got '-1'"),
    (["sim://?seed=9", "--master", "²"], "got '²'"),  # a digit to str.isdigit, not to int()
    (["sim://?seed=9", "sim://?seed=10", "--master", "2"], "expected 0..1"),
    (["sim://?seed=9", "--token", ""], "must not be empty: give the token, or 'auto' for a random one"),
    (["sim://?seed=9", "--token", "  "], "must not be empty"),
    (["sim://?seed=9", "sim://?seed=10", "--token", ""], "must not be empty"),
    (["sim://?seed=9", "--token", "my token"], "may hold only letters, digits"),  # the printed address
    (["sim://?seed=9", "--token", "a;b&c"], "got '&;'"),  # ';' cut the cookie, '&' the query
    (["sim://?seed=9", "--token", "50%"], "got '%'")])
def test_a_master_or_token_that_cannot_work_is_a_usage_error_before_any_camera(monkeypatch, capsys, argv, words):
    from stereocam.tools import cli

    def opened(*args: object, **kwargs: object) -> None:
        raise AssertionError("a camera was opened")

    monkeypatch.setattr("stereocam.tools.viewer.command.stereocam.open", opened)
    monkeypatch.setattr("stereocam.tools.viewer.command.stereocam.CameraGroup", opened)
    assert cli.main(["view", "--no-browser", *argv]) == 2
    err = capsys.readouterr().err
    option = "'--token'" if "--token" in argv else "'--master'"
    assert words in err and option in err and "Traceback" not in err
