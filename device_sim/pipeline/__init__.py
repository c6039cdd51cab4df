"""The firmware's capture pipeline: when to expose (capture_engine), then expose both sensors,
rectify, match (stereo), segment into messages and send (capture_pipeline)."""
