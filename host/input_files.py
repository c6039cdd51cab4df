"""Input files opened safely: only a regular file is read (a FIFO would block, a device never end,
a folder is not data) and only up to a size fixed before reading; a missing file is a typed error."""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

from stereocam.protocol.errors import InputFileError, MissingInputError, StereoCamError


def open_regular(path: str | Path, *, what: str = "file", limit: int | None = None,
                 error: type[StereoCamError] = InputFileError) -> BinaryIO:
    """``path`` opened for reading if it is a regular file of at most ``limit`` bytes; else ``error``
    (MissingInputError if it does not exist). The open never blocks and never reads before the check."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # a FIFO must not block the open
    except FileNotFoundError as exc:
        raise MissingInputError(f"the {what} {path} does not exist") from exc
    except OSError as exc:
        raise error(f"cannot read the {what} {path}: {exc.strerror or exc}") from exc
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"the {what} {path} is not a regular file (a FIFO, a device or a folder): refused unread")
        if limit is not None and st.st_size > limit:
            raise error(f"the {what} {path} is {st.st_size} bytes, more than the {limit} it can be: refused unread")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | Path, *, what: str = "file", limit: int,
                 error: type[StereoCamError] = InputFileError) -> bytes:
    """The bytes of ``path``, checked as ``open_regular`` does (a file growing past ``limit`` meanwhile
    is refused too)."""
    with open_regular(path, what=what, limit=limit, error=error) as f:
        try:
            data = f.read(limit + 1)
        except OSError as exc:
            raise error(f"cannot read the {what} {path}: {exc.strerror or exc}") from exc
    if len(data) > limit:
        raise error(f"the {what} {path} grew past the {limit} bytes it can be while read: refused")
    return data
