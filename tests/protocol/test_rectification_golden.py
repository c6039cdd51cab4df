"""Golden vectors of the rectified geometry (SPEC §12.6): calibration bodies of every lens model ->
f, cx, cy, B at several stream sizes and map samples; bodies a device must refuse, with the field.

``protocol/golden/rectification.json`` ships in the package for firmware teams. A failure here means
the geometry a device reports changed: old hosts would count every frame as a geometry mismatch.
Regenerate ONLY for a deliberate change of §12.6 (and say so in SPEC.md):

    .venv/bin/python -m tests.protocol.test_rectification_golden --regenerate
"""
from __future__ import annotations

import json
import sys
from importlib import resources
from typing import Any

import cv2
import numpy as np
import pytest

from stereocam.device_sim.calibration.acceptance import usable_calibration
from stereocam.device_sim.calibration.rectify import undistort_rectify_map
from stereocam.device_sim.rig.lens import LensClass, lens_calibration
from stereocam.protocol.calibration import CalibrationFormatError, StereoCalibration
from stereocam.protocol.calibration_limits import CalibrationImplausible, PlausibilityLimits
from stereocam.protocol.rectification import EQUIDISTANT_FOV_DEG, rectified_to_raw, rodrigues, stereo_rectify
from tests.support import paths

SOURCE = paths.REPO / "protocol" / "golden" / "rectification.json"
SIZES = ((1280, 960), (640, 480), (320, 240))
TOLERANCE = {"f_rel": 1e-5, "B_rel": 1e-5, "c_px": 1e-3, "map_px": 2e-3}
LIMITS = PlausibilityLimits(sensor_size=(1280, 960))  # the reference unit's sensor


def _with(c: StereoCalibration, **changes: Any) -> StereoCalibration:
    f = dict(image_size=c.image_size, K_left=c.K_left, D_left=c.D_left, K_right=c.K_right, D_right=c.D_right,
             R=c.R, T=c.T, lens_model=c.lens_model)
    return StereoCalibration(**{**f, **changes})


def _accepted() -> list[tuple[str, StereoCalibration, float]]:
    """(name, calibration, rectified_fov) of every accepted vector."""
    fish = lens_calibration(0, LensClass.FISHEYE)
    narrow = np.diag([3.0, 3.0, 1.0])
    narrow[:2, 2] = [-2 * 639.5, -2 * 479.5]  # f x3 about the image centre: a ~60 degree equidistant lens
    fov = EQUIDISTANT_FOV_DEG
    return [("plumb_bob: simulated standard unit, seed 0", lens_calibration(0, LensClass.STANDARD), fov),
            ("plumb_bob: simulated standard unit, seed 5", lens_calibration(5, LensClass.STANDARD), fov),
            ("rational_polynomial: simulated 120 deg wide unit, seed 0", lens_calibration(0, LensClass.WIDE), fov),
            ("equidistant: simulated 180 deg fisheye unit, seed 0", fish, fov),
            ("equidistant: 60 deg lens (the focal that keeps every pixel on the sensor wins over the "
             f"{EQUIDISTANT_FOV_DEG:g} deg field)",
             _with(fish, K_left=narrow @ fish.K_left, K_right=narrow @ fish.K_right), fov),
            ("equidistant: simulated 180 deg fisheye unit, seed 0, rectified_fov 150", fish, 150.0),
            ("equidistant: simulated 180 deg fisheye unit, seed 0, rectified_fov 60", fish, 60.0)]


def _refused() -> list[tuple[str, bytes]]:
    std = lens_calibration(0, LensClass.STANDARD)
    fish = lens_calibration(0, LensClass.FISHEYE)
    bad_version = bytearray(std.to_bytes())
    bad_version[0] = 3
    return [("vertical head", _with(std, R=np.eye(3), T=np.array([0.0, -0.1, 0.0])).to_bytes()),
            ("focal length of 0.05 image widths", _with(std, K_left=np.diag([64.0, 64.0, 1.0]) + std.K_left
                                                         * np.array([[0, 0, 1], [0, 0, 1], [0, 0, 0]])).to_bytes()),
            ("baseline of 1 mm", _with(std, T=std.T / np.linalg.norm(std.T) * 0.001).to_bytes()),
            ("cameras turned 40 deg against each other", _with(std, R=rodrigues(np.radians([0.0, 40.0, 0.0])))
             .to_bytes()),
            ("image size not a format of the 1280x960 sensor", std.scaled(1280, 720).to_bytes()),
            ("fisheye whose polynomial turns back between 35 and 59 deg off axis (folds)",
             _with(fish, D_left=np.array([-1.2, 0.5, 0.0, 0.0]), D_right=np.array([-1.2, 0.5, 0.0, 0.0])).to_bytes()),
            ("body_version 3", bytes(bad_version))]


def _samples(w: int, h: int) -> np.ndarray:
    return np.array([[0.0, 0.0], [w - 1.0, 0.0], [0.0, h - 1.0], [w - 1.0, h - 1.0], [(w - 1) / 2, (h - 1) / 2],
                     [w / 4, h / 3], [w * 0.9, h * 0.55]])


def _refusal(body: bytes) -> tuple[str, str]:
    try:
        usable_calibration(body, LIMITS)
    except CalibrationImplausible as exc:
        return exc.field, str(exc)
    except CalibrationFormatError as exc:
        return "format", str(exc)
    return "", ""


def build_golden() -> dict[str, Any]:
    accepted = []
    for name, calib, fov in _accepted():
        sizes = []
        for w, h in SIZES:
            c = calib.scaled(w, h)
            g = stereo_rectify(c, fov)
            pts = _samples(w, h)
            sizes.append({"width": w, "height": h, "f": g.focal_px, "cx": g.cx, "cy": g.cy, "B": g.baseline_m,
                          "map_samples": [{"u": float(u), "v": float(v), "left": left.tolist(), "right": right.tolist()}
                                          for (u, v), left, right in zip(
                                              pts, rectified_to_raw(c.K_left, c.D_left, c.lens_model, g.R1, g.P1, pts),
                                              rectified_to_raw(c.K_right, c.D_right, c.lens_model, g.R2, g.P2, pts))]})
        accepted.append({"name": name, "lens_model": calib.lens_model, "rectified_fov": fov,
                         "body_hex": calib.to_bytes().hex(), "sizes": sizes})
    refused = []
    for name, body in _refused():
        field, message = _refusal(body)
        refused.append({"name": name, "body_hex": body.hex(), "field": field, "message": message})
    return {"spec": "SPEC §12.6 rectified geometry (steps 1-5) and §12.4 step 4 refusals",
            "sensor_size": [1280, 960], "tolerance": TOLERANCE,
            "accepted": accepted, "refused": refused}


def _golden() -> dict[str, Any]:
    return json.loads(resources.files("stereocam.protocol").joinpath("golden/rectification.json").read_text())


def _same(shipped: Any, built: Any, where: str = "") -> list[str]:
    """Where shipped and built differ: structure, strings and integers exactly, floats to 1e-9
    (numpy's and libm's vector paths differ by CPU in the last bits: 1e-13 px was seen between
    an AVX-512 and an AVX2 machine; the tolerances a firmware must meet are 1e-5 and 1e-3 px)."""
    if isinstance(shipped, float) and isinstance(built, float):
        return [] if abs(shipped - built) <= 1e-9 * max(1.0, abs(shipped)) else [where]
    if isinstance(shipped, dict) and isinstance(built, dict):
        if shipped.keys() != built.keys():
            return [f"{where} keys"]
        return [d for k in shipped for d in _same(shipped[k], built[k], f"{where}.{k}")]
    if isinstance(shipped, list) and isinstance(built, list):
        if len(shipped) != len(built):
            return [f"{where} length"]
        return [d for i, (u, v) in enumerate(zip(shipped, built)) for d in _same(u, v, f"{where}[{i}]")]
    return [] if type(shipped) is type(built) and shipped == built else [where]


def test_the_shipped_file_is_the_one_this_code_generates() -> None:
    differs = _same(_golden(), json.loads(json.dumps(build_golden())))
    assert not differs, f"rectification golden vectors changed at {differs[:5]}: see this module's docstring"


def test_a_changed_golden_value_is_found() -> None:
    built = json.loads(json.dumps(build_golden()))
    assert _same(built, built) == []
    moved = json.loads(json.dumps(built))
    moved["accepted"][0]["sizes"][0]["f"] *= 1 + 1e-7
    moved["refused"][0]["field"] += "x"
    assert _same(built, moved) == [".accepted[0].sizes[0].f", ".refused[0].field"]


@pytest.mark.parametrize("case", range(len(_accepted())))
def test_the_firmware_reproduces_every_accepted_body(case: int) -> None:
    """Geometry from the body alone (as a firmware parses it), and the device's float32 maps."""
    entry = _golden()["accepted"][case]
    tol = _golden()["tolerance"]
    calib = usable_calibration(bytes.fromhex(entry["body_hex"]), LIMITS)
    for size in entry["sizes"]:
        c = calib.scaled(size["width"], size["height"])
        g = stereo_rectify(c, entry["rectified_fov"])
        assert g.focal_px == pytest.approx(size["f"], rel=tol["f_rel"])
        assert g.baseline_m == pytest.approx(size["B"], rel=tol["B_rel"])
        assert abs(g.cx - size["cx"]) <= tol["c_px"] and abs(g.cy - size["cy"]) <= tol["c_px"]
        for side, K, D, R, P in (("left", c.K_left, c.D_left, g.R1, g.P1), ("right", c.K_right, c.D_right, g.R2, g.P2)):
            mx, my = undistort_rectify_map(K, D, R, P, c.image_size, c.lens_model)
            for s in size["map_samples"]:
                if s["u"] == int(s["u"]) and s["v"] == int(s["v"]):  # a table entry
                    got = (mx[int(s["v"]), int(s["u"])], my[int(s["v"]), int(s["u"])])
                    assert np.hypot(got[0] - s[side][0], got[1] - s[side][1]) <= tol["map_px"], (side, s)


def test_plumb_bob_vectors_are_what_opencv_computes() -> None:
    """An oracle outside this code: for plumb_bob the geometry is cv2.stereoRectify's (alpha 0, zero disparity)."""
    for entry in _golden()["accepted"]:
        if entry["lens_model"] != "plumb_bob":
            continue
        calib = StereoCalibration.from_bytes(bytes.fromhex(entry["body_hex"]))
        for size in entry["sizes"]:
            c = calib.scaled(size["width"], size["height"])
            _, _, P1, P2, _ = cv2.stereoRectify(c.K_left, c.D_left, c.K_right, c.D_right, c.image_size, c.R,
                                                c.T.reshape(3, 1), flags=cv2.CALIB_ZERO_DISPARITY, alpha=0)[:5]
            assert P1[0, 0] == pytest.approx(size["f"], rel=1e-5)
            assert abs(P1[0, 2] - size["cx"]) < 1e-3 and abs(P1[1, 2] - size["cy"]) < 1e-3
            assert -P2[0, 3] / P2[0, 0] == pytest.approx(size["B"], rel=1e-5)


def test_every_refused_body_is_refused_for_its_reason() -> None:
    refused = _golden()["refused"]
    assert {r["field"] for r in refused} >= {"rectification", "K_left", "T", "R", "image_size", "format"}
    for r in refused:
        assert _refusal(bytes.fromhex(r["body_hex"]))[0] == r["field"], r["name"]


def regenerate() -> None:
    SOURCE.parent.mkdir(parents=True, exist_ok=True)
    SOURCE.write_text(json.dumps(build_golden(), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {SOURCE}")


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        sys.exit(__doc__)
    regenerate()
