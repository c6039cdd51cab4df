"""The firmware's link layer: bytes in, decoded requests, the replay cache, refusals as NACKs, bytes out."""
