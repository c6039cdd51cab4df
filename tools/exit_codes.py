"""The exit codes every ``stereocam`` command shares (tools/cli.py turns errors into them)."""
from __future__ import annotations

EXIT_OK, EXIT_CAMERA, EXIT_USAGE, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 0, 1, 2, 130, 141
EXIT_CODES = """Exit codes: 0 success; 1 camera error (unreachable, refused, timed out); 2 bad usage or
input (unknown option, a path that cannot be written); 3-7 calibrate's own (see its --help);
130 interrupted (Ctrl-C); 141 output closed early (for example piped into head)."""
