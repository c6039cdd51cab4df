"""Identity: INFO, capabilities, STATUS, and the answers to requests the device cannot execute."""
from __future__ import annotations

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.framing import MAX_PAYLOAD, VERSION_MAJOR
from stereocam.protocol.params import BY_NAME

from ..context import CAPABILITY_NAMES, Context
from ..registry import check
from ..results import expect

KNOWN_CAPABILITIES = sum(CAPABILITY_NAMES)
UNKNOWN_REQUEST = 0x3FFE  # in the request range, never assigned by protocol v1


@check("identity.info", "R-4.1-1", "R-7-3")
def info_sane(ctx: Context) -> str:
    """INFO: major 1, identity strings, limits within the SPEC's bounds, stable across reads."""
    i = ctx.info
    expect(i.protocol_version[0] == VERSION_MAJOR, f"protocol major {i.protocol_version[0]}, expected {VERSION_MAJOR}")
    expect(i.model.strip() and i.serial.strip() and i.firmware_version.strip(),
           f"empty identity string: model {i.model!r} serial {i.serial!r} firmware {i.firmware_version!r}")
    expect(0 < i.max_payload <= MAX_PAYLOAD, f"max_payload {i.max_payload} outside 1..{MAX_PAYLOAD}")
    w, h = BY_NAME["width"], BY_NAME["height"]
    expect(w.lo <= i.max_width <= w.hi, f"max_width {i.max_width} outside the width range {w.lo}..{w.hi}")
    expect(h.lo <= i.max_height <= h.hi, f"max_height {i.max_height} outside the height range {h.lo}..{h.hi}")
    expect(i.sensor_width > 0 and i.sensor_height > 0, f"sensor {i.sensor_width}x{i.sensor_height}")
    expect(not i.stage_limits or i.protocol_version >= (1, 3), "stage limits (a 1.3 field) from an older device")
    beyond = [lim for lim in i.stage_limits if lim[1] > i.max_width or lim[2] > i.max_height or not all(lim)]
    expect(not beyond, f"stage limits {beyond} beyond max_width x max_height {i.max_width}x{i.max_height} or zero")
    again = ctx.s.call(m.GetInfo())
    assert isinstance(again, m.Info)
    expect(again.serial == i.serial and again.model == i.model, "a second INFO names another unit")
    return (f"{i.model} serial {i.serial} firmware {i.firmware_version} protocol {i.protocol_version[0]}."
            f"{i.protocol_version[1]}, max {i.max_width}x{i.max_height}, max_payload {i.max_payload}")


@check("identity.capabilities", "R-4.1-2")
def capabilities(ctx: Context) -> str:
    """Capability bits: known ones named; unknown ones allowed (later minors) but reported."""
    caps = ctx.info.capabilities
    names = [name for bit, name in CAPABILITY_NAMES.items() if caps & bit]
    extra = caps & ~KNOWN_CAPABILITIES
    if caps & m.Capability.CALIBRATION:
        expect(ctx.info.protocol_version >= (1, 1), "CALIBRATION advertised by a protocol 1.0 device")
    if "rectify" in ctx.params:
        expect(ctx.info.protocol_version >= (1, 1), "rectify (a 1.1 parameter) on a protocol 1.0 device")
    for bit in (m.Capability.FRAME_REPAIR, m.Capability.FIRMWARE_UPDATE, m.Capability.TRIGGER_OUTPUT):
        expect(not caps & bit or ctx.info.protocol_version >= (1, 2),
               f"{CAPABILITY_NAMES[bit]} (a 1.2 capability) advertised by a protocol "
               f"{ctx.info.protocol_version[0]}.{ctx.info.protocol_version[1]} device")
    expect(not caps & m.Capability.SGM or ctx.info.protocol_version >= (1, 3),
           "SGM (a 1.3 capability bit) advertised by an older device")
    return f"0x{caps:08x}: {', '.join(names) or 'none'}" + (f"; unknown bits 0x{extra:x} (ignored)" if extra else "")


@check("identity.status", "R-4.7-1")
def status(ctx: Context) -> str:
    """STATUS: at least the 14 v1 counters, state matching the config, counters monotonic."""
    a = ctx.status()
    b = ctx.status()
    expect(len(a.counters) >= len(m.COUNTERS), f"{len(a.counters)} counters, at least {len(m.COUNTERS)} expected")
    expect(not a.streaming, "streaming after STOP")
    mode = ctx.config().get("trigger_mode")
    expect(mode is None or a.trigger_mode == mode, f"STATUS trigger_mode {a.trigger_mode}, CONFIG {mode}")
    back = [k for k in a.counters if b.counters[k] < a.counters[k]]
    expect(not back, f"counters went back: {back}")
    expect(b.uptime_us > a.uptime_us, f"uptime_us {a.uptime_us} then {b.uptime_us}")
    expect(b.counters["rx_packets"] > a.counters["rx_packets"], "rx_packets did not count the HEARTBEAT")
    return f"{len(a.counters)} counters, uptime {a.uptime_us / 1e6:.1f} s"


# SPEC §4.0 capability groups: one harmless probe per group (an empty payload a known request
# refuses BAD_PAYLOAD, or a read), which must be UNKNOWN_TYPE exactly when the bit is clear
GROUP_PROBES = ((m.Capability.CALIBRATION, m.MsgType.CALIB_READ), (m.Capability.FRAME_REPAIR, m.MsgType.SET_FRAME_LINK),
                (m.Capability.FIRMWARE_UPDATE, m.MsgType.UPDATE_BEGIN))


@check("identity.unknown_type", "R-4.0-2", "R-4.0-3")
def unknown_type(ctx: Context) -> str:
    """A request type the device does not know, and an event type sent to it: NACK UNKNOWN_TYPE; a
    request of a capability group: UNKNOWN_TYPE exactly when INFO lacks the group's bit."""
    for msg_type in (UNKNOWN_REQUEST, int(m.MsgType.FRAME_BEGIN), int(m.MsgType.INFO)):
        reply = ctx.s.wait_reply(ctx.s.send_frame(msg_type, b""))
        n = reply.message
        expect(isinstance(n, m.Nack), f"type 0x{msg_type:04x} answered with 0x{reply.packet.msg_type:04x}, not NACK")
        assert isinstance(n, m.Nack)
        expect(n.code == ErrorCode.UNKNOWN_TYPE and n.param_id == 0 and n.request_type == msg_type,
               f"type 0x{msg_type:04x}: NACK code {n.code} param {n.param_id} request_type 0x{n.request_type:04x}, "
               f"expected UNKNOWN_TYPE, 0, 0x{msg_type:04x}")
    groups = []
    for bit, msg_type in GROUP_PROBES:
        if ctx.info.protocol_version < ((1, 1) if bit == m.Capability.CALIBRATION else (1, 2)):
            continue  # a request type its minor does not know: covered above
        n = ctx.s.wait_reply(ctx.s.send_frame(msg_type, b"")).message
        unknown = isinstance(n, m.Nack) and n.code == ErrorCode.UNKNOWN_TYPE
        has = ctx.has(bit)
        expect(unknown != has, f"{m.MsgType(msg_type).name} (group {CAPABILITY_NAMES[bit]}, "
                               f"{'advertised' if has else 'not advertised'}): "
                               f"{'NACK UNKNOWN_TYPE' if unknown else 'known'}")
        groups.append(f"{CAPABILITY_NAMES[bit]} {'known' if has else 'UNKNOWN_TYPE'}")
    return f"unknown request, event and reply types all NACKed UNKNOWN_TYPE; groups: {', '.join(groups)}"


@check("identity.bad_payload", "R-4.0-1")
def bad_payload(ctx: Context) -> str:
    """Malformed payloads of known requests: NACK BAD_PAYLOAD, nothing executed."""
    before = ctx.config()
    cases = [(m.MsgType.GET_INFO, b"\x00", "non-empty GET_INFO"),
             (m.MsgType.START, b"\x01\x02", "non-empty START"),
             (m.MsgType.SET_CONFIG, b"\x01\x00\x05\x00\x00\x00", "param list one byte short"),
             (m.MsgType.SET_CONFIG, b"\x00\x00\x05\x00\x00\x00\x00\x00", "param list with trailing bytes")]
    for msg_type, payload, what in cases:
        n = ctx.s.wait_reply(ctx.s.send_frame(msg_type, payload)).message
        expect(isinstance(n, m.Nack) and n.code == ErrorCode.BAD_PAYLOAD,
               f"{what}: answered {n!r}, expected NACK BAD_PAYLOAD")
    expect(not ctx.status().streaming, "a malformed START started the stream")
    expect(ctx.config() == before, "a malformed SET_CONFIG changed the configuration")
    return f"{len(cases)} malformed requests NACKed BAD_PAYLOAD"
