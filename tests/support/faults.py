"""Fault injection for the tests: the transport wrapper and line noise live in the package
(``stereocam.tools.soak.fault_link``, shared with ``stereocam soak``); packet-level rules live here."""
from __future__ import annotations

import dataclasses
from typing import Callable

from stereocam.protocol import messages as m
from stereocam.protocol.framing import Decoder, encode_frame
from stereocam.tools.soak.fault_link import FaultyTransport, LineNoise, Manipulator

__all__ = ["FaultyTransport", "LineNoise", "Manipulator", "PacketFilter"]


class PacketFilter:
    """A read manipulator working on whole packets: ``rule(packet) -> bytes | None`` (None keeps it)."""

    def __init__(self, rule: Callable[[object], bytes | None]):
        self.decoder = Decoder()
        self.rule = rule

    def __call__(self, data: bytes) -> bytes:
        out = []
        for p in self.decoder.feed(data):
            replaced = self.rule(p)
            out.append(encode_frame(p.msg_type, p.request_id, p.payload, p.flags) if replaced is None else replaced)
        return b"".join(out)


def as_v1_1_info(p) -> bytes | None:
    """Rewrite INFO as a protocol 1.1 device sends it: no FRAME_REPAIR capability."""
    if p.msg_type != m.MsgType.INFO:
        return None
    info = m.decode_packet(p)
    return m.encode(dataclasses.replace(info, protocol_version=(1, 1),
                                        capabilities=info.capabilities & ~m.Capability.FRAME_REPAIR), p.request_id)


def as_v1_2_info(p) -> bytes | None:
    """Rewrite INFO as a protocol 1.2 device sends it: no SGM bit (1.2 had SGM without one) and the
    payload ending at usb_speed (no stage limits)."""
    if p.msg_type != m.MsgType.INFO:
        return None
    info = m.decode_packet(p)
    old = dataclasses.replace(info, protocol_version=(1, 2), capabilities=info.capabilities & ~m.Capability.SGM,
                              stage_limits=())
    return encode_frame(m.MsgType.INFO, p.request_id, old.pack()[:-1])  # the n_limits byte a 1.2 device lacks
