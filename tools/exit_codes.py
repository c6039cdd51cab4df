"""The exit codes every ``stereocam`` command shares (tools/cli.py turns errors into them)."""
from __future__ import annotations

EXIT_OK, EXIT_CAMERA, EXIT_USAGE, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 0, 1, 2, 130, 141
# calibrate's own (tools/calibration): no solution, a failed quality gate, the unit refused or lost the
# write, the outputs could not be saved, the unit cannot calibrate; calibration export: no calibration
EXIT_NO_SOLUTION, EXIT_GATE, EXIT_WRITE, EXIT_SAVE, EXIT_UNSUPPORTED = 3, 4, 5, 6, 7
EXIT_NO_CALIBRATION = 3
EXIT_CODES = """Exit codes: 0 success; 1 the camera or a file failed (unreachable, refused, timed out; a
recording, image or key that is damaged or refused); 2 bad usage, checked before any camera is
touched where it can be (unknown option, a bad value, a URL without a port, a path that cannot be
written or is missing; a configuration the camera refuses is a bad value too); 3-7 calibrate's own
(see its --help); 130 interrupted (Ctrl-C); 141 output closed before everything was written (a
reader such as head that exits early)."""
