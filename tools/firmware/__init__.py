"""stereocam firmware: signed firmware images (keygen, sign, update a camera, slot status)."""
