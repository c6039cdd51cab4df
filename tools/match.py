"""``stereocam match LEFT RIGHT --out FILE``: a disparity map from two rectified image files, made by
the camera's own engines and post-processing presets (the same code the simulated device runs), and
written in a format other tools read: a 16-bit PNG as KITTI's (disparity x 256, 0 no match, so a
zero disparity is written as 1 / 256 px), PFM as Middlebury's (inf no match) or .npy (float32, NaN no
match). The bench reads all three back as truth (``bench matching --pair ... --truth``). A file is
written whole or not at all: an existing one is replaced only once the new one is complete."""
from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import click
import numba
import numpy as np

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME, defaults
from stereocam.stereo import engines
from stereocam.stereo.config_map import config_of
from stereocam.stereo.post import POST_PRESETS, postprocess, post_params_from_config, preset_config
from stereocam.tools.camera.pictures import colorize_px
from stereocam.tools.image_files import read_pair
from stereocam.tools.options import CONTEXT, SETTING, epilog, multiple_of_16, output_file

FORMATS = (".png", ".pfm", ".npy")
KITTI_SCALE = 256  # a 16-bit PNG holds disparity x 256, 0 where there is no match


def match_config(algorithm: str | None, preset: str, num_disparities: int, min_disparity: int) -> dict[str, int]:
    """The device configuration ``match`` runs: with no preset the engine's library defaults (as
    ``match(left, right, SGMParams(num_disparities=...))`` and the bench's raw rows), with one the
    preset as a device applies it (as the bench's preset rows)."""
    settings = preset_config(preset)
    name = algorithm or (engines.engine_for(settings["algorithm"]).name if preset != "off" else "sgm")
    engine = engines.engine_named(name)
    if preset != "off":
        return {**defaults(), **settings, "algorithm": engine.algorithm, "num_disparities": num_disparities,
                "min_disparity": min_disparity}
    try:
        params = engine.params(num_disparities=num_disparities, min_disparity=min_disparity)
    except ValueError as exc:  # the parameter classes name the value
        raise ConfigError(str(exc)) from exc
    return {**defaults(), **settings, **config_of(params, engine.config), "algorithm": engine.algorithm}


def disparity_map(left: np.ndarray, right: np.ndarray, config: dict[str, int]) -> np.ndarray:
    """Disparity in pixels (float32, NaN where there is no match) of a device configuration:
    its engine, then its post-processing chain."""
    try:
        params = engines.params_from_config(config)
        matcher = engines.matcher_for(config, left.shape)
    except ValueError as exc:  # the parameter classes name the value
        raise ConfigError(str(exc)) from exc
    raw = matcher.match(left, right)
    out = postprocess(raw, left, post_params_from_config(config), right, params)
    return np.where(out == params.invalid_value, np.nan, out.astype(np.float32) / 16).astype(np.float32)


def write_whole(path: Path, write: Callable[[Path], None]) -> None:
    """``write(tmp)`` to a new file beside ``path`` (same suffix: OpenCV picks its encoder by it), then
    that file renamed over ``path``; on any failure the new file is removed and ``path`` is untouched."""
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _imwrite(image: np.ndarray) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        import cv2

        if not cv2.imwrite(str(path), image):
            raise OSError(f"{path}: OpenCV could not write it")
    return write


def write_disparity(path: Path, disparity: np.ndarray) -> None:
    """``disparity`` (float32 px, NaN no match) in the format ``path``'s suffix names (FORMATS)."""
    suffix = path.suffix.lower()
    known = np.isfinite(disparity)
    if suffix == ".npy":
        write_whole(path, lambda tmp: np.save(tmp, disparity))
    elif suffix == ".pfm":
        write_whole(path, _imwrite(np.where(known, disparity, np.inf).astype(np.float32)))
    else:
        if np.nanmin(disparity, initial=0.0) < 0:
            raise ConfigError("a 16-bit PNG holds no negative disparity: write .pfm or .npy")
        # 0 means no match in this format: a zero disparity (a point at infinity) is kept as 1 / 256 px
        code = np.where(known, np.maximum(np.rint(disparity * KITTI_SCALE), 1), 0)
        write_whole(path, _imwrite(np.clip(code, 0, 65535).astype(np.uint16)))


def _format(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    path = output_file(ctx, param, value)
    if path is not None and path.suffix.lower() not in FORMATS:
        raise click.BadParameter(f"{path.name}: the suffix names the format, one of {', '.join(FORMATS)}")
    return path


def _picture(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    path = output_file(ctx, param, value)
    if path is not None and path.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise click.BadParameter(f"{path.name}: a picture is .png or .jpg")
    return path


def _matching_settings(ctx: click.Context, param: click.Parameter,
                       value: tuple[tuple[str, int], ...]) -> tuple[tuple[str, int], ...]:
    allowed = engines.matching_names()
    for name, number in value:
        if name not in allowed:
            raise click.BadParameter(f"{name}: not a matching parameter; it takes {', '.join(allowed)}")
        why = BY_NAME[name].check(number)
        if why:
            raise click.BadParameter(why)
    return value


_FILE = click.Path(exists=True, dir_okay=False, path_type=Path)


@click.command("match", context_settings=CONTEXT, epilog=epilog())
@click.argument("left", type=_FILE)
@click.argument("right", type=_FILE)
@click.option("--out", required=True, type=click.Path(path_type=str), callback=_format, metavar="FILE",
              help="The disparity map: .png (16-bit, disparity x 256, 0 no match: KITTI's), .pfm (float, inf no "
                   "match: Middlebury's) or .npy (float32, NaN no match).")
@click.option("--algorithm", type=click.Choice(engines.names()), default=None,
              help="The engine.  [default: the preset's, else sgm]")
@click.option("--num-disparities", type=click.IntRange(min=16), default=128, show_default=True,
              callback=multiple_of_16, metavar="D", help="Disparities searched (a multiple of 16).")
@click.option("--min-disparity", type=int, default=0, show_default=True, metavar="D",
              help="The smallest disparity searched.")
@click.option("--preset", type=click.Choice(list(POST_PRESETS)), default="off", show_default=True,
              help="Post-processing preset (the engine settings and chain it names): high_density fills every "
                   "pixel, high_accuracy keeps the surer ones.")
@click.option("--preview", type=click.Path(path_type=str), callback=_picture, default=None, metavar="PNG",
              help="Also a picture to look at: the disparities colour-mapped over the searched range, no match "
                   "black.")
@click.option("--set", "settings", type=SETTING, multiple=True, callback=_matching_settings,
              help="A matching or post-processing parameter (as `info` prints them, e.g. block_size=9, sgm_p2=128, "
                   "hole_fill=1), applied last (repeatable).")
def command(left: Path, right: Path, out: Path, algorithm: str | None, num_disparities: int, min_disparity: int,
            preset: str, preview: Path | None, settings: tuple[tuple[str, int], ...]) -> None:
    """A disparity map from two rectified image files (colour turned grey), by the camera's engines."""
    if out.suffix.lower() == ".png" and min_disparity < 0:
        raise click.BadParameter("a 16-bit PNG holds no negative disparity: write .pfm or .npy",
                                 param_hint="'--min-disparity'")
    a, b = read_pair(left, right)
    config = {**match_config(algorithm, preset, num_disparities, min_disparity), **dict(settings)}
    engine = engines.engine_for(config["algorithm"])
    engine.warm_up()  # the kernels compiled (or loaded) before the clock starts
    t0 = time.perf_counter()
    disparity = disparity_map(a, b, config)
    ms = (time.perf_counter() - t0) * 1e3
    write_disparity(out, disparity)
    if preview is not None:
        lo = float(config["min_disparity"])
        write_whole(preview, _imwrite(colorize_px(disparity, (lo, lo + config["num_disparities"]))))
    share = 100.0 * float(np.isfinite(disparity).mean())
    click.echo(f"{out}: {a.shape[1]}x{a.shape[0]}, {engine.name}, preset {preset}, {share:.1f} % of pixels "
               f"matched, {ms:.1f} ms (one run, {numba.get_num_threads()} threads)")
