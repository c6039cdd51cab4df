"""Progress bars (tqdm, rich) only on a terminal: piped or logged output gets no carriage-return lines."""
from __future__ import annotations

import sys


def progress_wanted() -> bool:
    """True when stderr, where every progress bar is drawn, is a terminal."""
    return sys.stderr.isatty()
