"""``stereocam soak URL``: a long fuzz and fault run with counts, outside the CI suite (issue 9).

1. decoder fuzz: mutated frame streams into fresh decoders (default 1 000 000 inputs);
2. device fuzz: CRC-valid requests with mutated payloads to the device at URL, each must be answered;
3. streaming through a faulty link (byte flips, lost bytes, split writes, latency) at each --flip
   rate for --seconds, counting frames sent / delivered / corrupted / dropped and whether the
   device's and host's counters add up (corruption is checked against the device for sim:// URLs).
Exit status 1 on any crash, hang, corrupted frame, counters that do not add up, or a delivery rate
below its goal (VGA frames on a serial-class link: 95 % at 1 byte in 10^5 flipped, 50 % at 1 in 10^4).
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES

import argparse

from .parts import Report, fuzz_decoder, fuzz_device, stream_with_faults


def _print(rep: Report) -> None:
    print(f"{rep.name}: inputs {rep.inputs}, crashes {rep.crashes}, hangs {rep.hangs}")
    for key, value in rep.figures.items():
        print(f"    {key}: {value}")


DELIVERY_GOALS = {1e-5: 0.95, 1e-4: 0.50}  # byte flip rate -> share of the frames sent that must arrive


def _failed(rep: Report, flip: float | None = None) -> bool:
    f = rep.figures
    corrupted = f.get("corrupted", 0)
    goal = DELIVERY_GOALS.get(flip) if flip is not None else None
    short = goal is not None and f["delivered"] < goal * max(f["frames sent"], 1)
    if short:
        f["delivery goal"] = f"NOT MET (at least {goal:.0%})"
    elif goal is not None:
        f["delivery goal"] = f"met (at least {goal:.0%})"
    return bool(rep.crashes or rep.hangs or f.get("invariant violations") or short
                or (isinstance(corrupted, int) and corrupted)
                or str(f.get("counters add up", "yes")).startswith("NO"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam soak", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES)
    ap.add_argument("url", nargs="?", default="sim://?seed=1")
    ap.add_argument("--decoder-inputs", type=int, default=1_000_000)
    ap.add_argument("--device-inputs", type=int, default=5_000)
    ap.add_argument("--seconds", type=float, default=120.0, help="streaming time per flip rate")
    ap.add_argument("--flip", type=float, action="append", help="byte flip rate(s) (default 1e-5 and 1e-4)")
    ap.add_argument("--drop", type=float, default=1e-6, help="byte loss rate")
    ap.add_argument("--latency", type=float, default=0.001, help="max delay per chunk, s")
    ap.add_argument("--split", type=int, default=16, help="split host writes into pieces of 1..N bytes")
    ap.add_argument("--chunk", type=int, default=1024, help="FRAME_DATA bytes asked for (0: the transport's)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    runs = [(None, lambda: fuzz_decoder(args.decoder_inputs, args.seed)),
            (None, lambda: fuzz_device(args.url, args.device_inputs, args.seed))]
    runs += [(flip, lambda flip=flip: stream_with_faults(args.url, args.seconds, flip, args.drop, args.latency,
                                                         args.split, args.chunk or None, seed=args.seed))
             for flip in args.flip or [1e-5, 1e-4]]
    bad = []
    for flip, run in runs:  # one at a time, each printed as it ends
        rep = run()
        if _failed(rep, flip):
            bad.append(rep.name)
        _print(rep)
    print("soak: " + (f"FAILED ({', '.join(bad)})" if bad else "clean"))
    return 1 if bad else 0
