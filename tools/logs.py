"""Logging for the ``stereocam`` command: stereocam's loggers follow -v / -vv, every other library's
stays at warnings unless ``--log-level NAME=LEVEL`` asks for it."""
from __future__ import annotations

import logging
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TextIO

OWN = "stereocam"
LEVELS = ("CRITICAL", "ERROR", "WARNING", "INFO", "DEBUG")
FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


@dataclass(frozen=True)
class LogLevels:
    """stereocam's level and the levels asked for other loggers by name."""

    own: int = logging.WARNING
    named: dict[str, int] = field(default_factory=dict)

    def allows(self, record: logging.LogRecord) -> bool:
        """stereocam's records from its level on; another logger's from WARNING on, or from the level
        asked for it (or for a logger above it: ``distributed`` covers ``distributed.core``)."""
        if _under(record.name, OWN):
            return record.levelno >= self.own
        asked = [level for name, level in self.named.items() if _under(record.name, name)]
        return record.levelno >= (asked[-1] if asked else logging.WARNING)

    @property
    def lowest(self) -> int:
        """The most verbose level anything is asked at (never above WARNING)."""
        return min(logging.WARNING, self.own, *self.named.values())


class StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record comes (click and pytest swap it)."""

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: object) -> None:
        pass


def _under(name: str, parent: str) -> bool:
    return name == parent or name.startswith(parent + ".")


def parse_levels(verbose: int, specs: tuple[str, ...]) -> LogLevels:
    """``-v`` count and ``--log-level`` values (``LEVEL`` for stereocam's, ``NAME=LEVEL`` for a logger)
    as LogLevels; ValueError names a value that is not a level."""
    own = max(logging.DEBUG, logging.WARNING - 10 * verbose)
    named: dict[str, int] = {}
    for spec in specs:
        name, _, level = spec.rpartition("=")
        if level.upper() not in LEVELS or (spec.count("=") and not name):
            raise ValueError(f"{spec!r}: expected LEVEL or NAME=LEVEL, LEVEL one of {', '.join(LEVELS)} "
                             f"(any case)")
        value = logging.getLevelName(level.upper())
        if name and name != OWN:
            named[name] = value
        else:
            own = value
    return LogLevels(own, named)


def configure(levels: LogLevels) -> None:
    """One stderr handler on the root logger that lets through what ``levels`` allows."""
    handler = StderrHandler()
    handler.setFormatter(logging.Formatter(FORMAT))
    handler.addFilter(levels.allows)
    root = logging.getLogger()
    root.addHandler(handler)
    root.setLevel(levels.lowest)  # below it no record is made at all
    for name, level in levels.named.items():
        if _under(name, "distributed"):  # Dask sets its loggers' levels when imported: tell its config
            os.environ[f"DASK_LOGGING__{name.upper()}"] = logging.getLevelName(level).lower()


@contextmanager
def restored() -> Iterator[None]:
    """The root logger's level and handlers as they were before, afterwards (a command run in-process
    leaves no logging behind)."""
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    try:
        yield
    finally:
        for handler in root.handlers[:]:
            if handler not in handlers:
                root.removeHandler(handler)
        root.setLevel(level)
