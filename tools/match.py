"""``stereocam match LEFT RIGHT --out FILE``: a disparity map from two rectified image files, made by
the camera's own engines and post-processing presets (the same code the simulated device runs), and
written whole in a format other tools read (tools/image_files.py: a 16-bit PNG as KITTI's, PFM as
Middlebury's, .npy), which the bench reads back as truth (``bench matching --pair ... --truth``)."""
from __future__ import annotations

import time
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
from stereocam.tools.image_files import DISPARITY_FORMATS, imwrite, read_pair, write_disparity, write_whole
from stereocam.tools.options import CONTEXT, INPUT_FILE, SETTING, epilog, multiple_of_16, output_file



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


def _format(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    path = output_file(ctx, param, value)
    if path is not None and path.suffix.lower() not in DISPARITY_FORMATS:
        raise click.BadParameter(f"{path.name}: the suffix names the format, one of {', '.join(DISPARITY_FORMATS)}")
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




@click.command("match", context_settings=CONTEXT, epilog=epilog())
@click.argument("left", type=INPUT_FILE)
@click.argument("right", type=INPUT_FILE)
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
        write_whole(preview, imwrite(colorize_px(disparity, (lo, lo + config["num_disparities"]))))
    share = 100.0 * float(np.isfinite(disparity).mean())
    click.echo(f"{out}: {a.shape[1]}x{a.shape[0]}, {engine.name}, preset {preset}, {share:.1f} % of pixels "
               f"matched, {ms:.1f} ms (one run, {numba.get_num_threads()} threads)")
