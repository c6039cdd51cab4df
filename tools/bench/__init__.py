"""stereocam bench: benchmarks of the protocol, transports, USB, matching core, calibration, recordings."""
