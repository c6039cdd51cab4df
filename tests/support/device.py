"""What device tests share: the small format they run at."""

SMALL = {"width": 320, "height": 240, "num_disparities": 32, "block_size": 11}
"""A small format so device tests run fast."""
