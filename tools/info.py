"""``stereocam info URL``: identity, configuration and counters of one camera."""
from __future__ import annotations

import argparse

import stereocam


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam info", description=__doc__.splitlines()[0])
    ap.add_argument("url")
    args = ap.parse_args(argv)
    with stereocam.open(args.url, timeout=2.0) as cam:
        i = cam.info()
        print(f"model {i.model}\nserial {i.serial}\nfirmware {i.firmware_version}\n"
              f"protocol {i.protocol_version[0]}.{i.protocol_version[1]}\nsensor {i.sensor_width}x{i.sensor_height}\n"
              f"max_payload {i.max_payload}")
        for name, value in cam.config().items():
            print(f"config.{name} {value}")
        st = cam.status()
        print(f"uptime_s {st.uptime_us / 1e6:.1f}\nstreaming {st.streaming}")
        for name, value in st.counters.items():
            print(f"counter.{name} {value}")
    return 0
