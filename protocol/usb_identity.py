"""How a StereoCam unit looks on USB (SPEC §3.3): ids, interface and endpoints.

Shared by the host's USB transport and by any device implementation (the simulator's
descriptors), so the two sides can never disagree.
"""
from __future__ import annotations

VENDOR_ID = 0x1209
"""pid.codes' shared open-hardware vendor ID."""
PRODUCT_ID = 0x0001
"""pid.codes test PID (0x0001-0x0010 are reserved for testing); replace before shipping."""
CAMERA_IDS: tuple[tuple[int, int], ...] = ((VENDOR_ID, PRODUCT_ID),)
"""(VID, PID) pairs a host treats as StereoCam cameras."""
INTERFACE_CLASS = 0xFF
"""The camera's one interface is vendor-specific."""
INTERFACE_NUMBER = 0
EP_OUT = 0x01
"""Bulk OUT: host → device protocol bytes."""
EP_IN = 0x81
"""Bulk IN: device → host protocol bytes."""
MAX_PACKET_SIZE_HS = 512
"""wMaxPacketSize of a high-speed bulk endpoint (USB 2.0 §5.8.3)."""
MAX_PACKET_SIZE_SS = 1024
"""wMaxPacketSize of a super-speed bulk endpoint (USB 3.x §9.6.6)."""
