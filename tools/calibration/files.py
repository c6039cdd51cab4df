"""Which files of a calibration set are the left and right images of one pair.

Real sets come named many ways; all of these are understood (case does not matter):
  flat, a side word:    left01.png right01.png · left_07.jpg · cam_left-0003.png · stereo_right_3.bmp
  flat, a side letter:  L01.png R01.png · img_L_3.png · imgR3.png
  two folders:          left/ right/ · l/ r/ · cam0/ cam1/ · cam_left/ cam_right/ · image_left/ image_right/
A pair is the left and right image with the same number (the last run of digits in the name; in
two folders, the same file name when names carry no number). Images are .png .jpg .jpeg .bmp .pgm
.ppm .tif .tiff.
"""
from __future__ import annotations

import re
from pathlib import Path

IMAGE = re.compile(r"\.(png|jpe?g|bmp|pgm|ppm|tiff?)$", re.IGNORECASE)
# a side word not glued to a lower-case word before it ("bright" is no right), or capitalised ("imgLeft")
SIDE_WORD = re.compile(r"(?<![a-zA-Z])(?i:left|right)|(?<=[a-z])(?:Left|Right|LEFT|RIGHT)")
# a lone side letter ("L01", "img_R_3"), or a capital glued to a word and followed by a digit ("imgL3")
SIDE_LETTER = re.compile(r"(?<![a-zA-Z])([lLrR])(?![a-zA-Z])|(?<=[a-z])([LR])(?=\d)")
FOLDERS = (("left", "right"), ("l", "r"), ("cam0", "cam1"), ("cam_left", "cam_right"), ("image_left", "image_right"))
Pair = tuple[int, Path, Path]


def find_pairs(directory: Path) -> list[Pair]:
    """(number, left path, right path) for every number that has both images, sorted by number.
    ValueError (naming the problem) when none pair up or a number is taken twice."""
    if not directory.is_dir():
        raise ValueError(f"{directory} is not a directory")
    folders = {p.name.lower(): p for p in directory.iterdir() if p.is_dir()}
    for a, b in FOLDERS:
        if a in folders and b in folders:
            return _pair(directory, _keyed(folders[a], "left"), _keyed(folders[b], "right"))
    sides: dict[str, dict[int, Path]] = {"left": {}, "right": {}}
    for path in _images(directory):
        side = _side(path.stem)
        number = _number(path.stem)
        if side is None or number is None:
            continue
        if number in sides[side]:
            raise ValueError(f"two {side} images with number {number}: {sides[side][number].name}, {path.name}")
        sides[side][number] = path
    return _pair(directory, sides["left"], sides["right"])


def _images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and IMAGE.search(p.name))


def _side(stem: str) -> str | None:
    words = {w.lower() for w in SIDE_WORD.findall(stem)}
    if len(words) == 1:
        return words.pop()
    if words:
        return None  # both words: not one side's image
    letters = {(m.group(1) or m.group(2)).lower() for m in SIDE_LETTER.finditer(stem)}
    return {"l": "left", "r": "right"}[letters.pop()] if len(letters) == 1 else None


def _number(stem: str) -> int | None:
    digits = re.findall(r"\d+", stem)
    return int(digits[-1]) if digits else None


def _keyed(folder: Path, side: str) -> dict[int, Path] | dict[str, Path]:
    """A folder's images by number, or by file name when the names carry no number."""
    images = _images(folder)
    if images and all(_number(p.stem) is None for p in images):
        return {p.name: p for p in images}
    out: dict[int, Path] = {}
    for path in images:
        number = _number(path.stem)
        if number is None:
            continue
        if number in out:
            raise ValueError(f"two {side} images with number {number}: {out[number].name}, {path.name}")
        out[number] = path
    return out


def _pair(directory: Path, left: dict, right: dict) -> list[Pair]:
    common = sorted(set(left) & set(right), key=lambda k: (isinstance(k, str), k))
    if not common:
        raise ValueError(f"no left<N>/right<N> image pairs in {directory} (names like left01.png/right01.png, "
                         "L01.png/R01.png, or the folders left/ and right/)")
    return [(k if isinstance(k, int) else i, left[k], right[k]) for i, k in enumerate(common)]
