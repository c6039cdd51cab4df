"""``stereocam firmware keygen|sign|update|status``: signed firmware images and field updates.

    stereocam firmware keygen --out KEY                  (KEY: Ed25519 private key, KEY.pub: its public half)
    stereocam firmware sign --key KEY --version V --out IMAGE BUILD.json [--security-counter N] [--code BIN]
    stereocam firmware update URL IMAGE [--replace]      (progress bar; success only once the unit runs it)
    stereocam firmware status URL                        (both slots: version, state, hash, confirmed)
"""
from __future__ import annotations

from stereocam.tools.exit_codes import EXIT_CODES

import argparse
import json
from pathlib import Path

from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from rich.console import Console
from rich.progress import BarColumn, DownloadColumn, Progress, TransferSpeedColumn
from rich.table import Table

import stereocam
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.firmware_image import (FirmwareBuild, build_image, inspect_image, load_private_key,
                                               private_key_pem, public_key_pem)
from stereocam.protocol.params import BY_NAME

DEFAULT_TARGET = "STOC-SIM"


def keygen(args: argparse.Namespace) -> int:
    key = Ed25519PrivateKey.generate()
    args.out.write_bytes(private_key_pem(key))
    args.out.chmod(0o600)
    pub = args.out.with_name(args.out.name + ".pub")
    pub.write_bytes(public_key_pem(key.public_key()))
    print(f"wrote {args.out} (private, keep it secret) and {pub}")
    return 0


def _read(path: Path, what: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read the {what} {path}: {exc}") from exc


def sign(args: argparse.Namespace) -> int:
    key = load_private_key(_read(args.key, "key"))
    build = FirmwareBuild.from_json(_read(args.build, "build"))
    build = FirmwareBuild(args.version, build.protocol_minor, build.capabilities, build.parameter_defaults)
    for name, value in build.parameter_defaults.items():
        if name not in BY_NAME or BY_NAME[name].check(value) is not None:
            raise ConfigError(f"parameter default {name}={value}: "
                              f"{BY_NAME[name].check(value) if name in BY_NAME else 'no such parameter'}")
    code = _read(args.code, "code") if args.code else b""
    image = build_image(build, key, target=args.target, security_counter=args.security_counter, code=code)
    args.out.write_bytes(image)
    print(f"wrote {args.out}: {len(image)} bytes, version {build.version}, target {args.target}")
    return 0


def update(args: argparse.Namespace) -> int:
    image = _read(args.image, "image")
    console = Console(stderr=True)
    with stereocam.open(args.url, timeout=args.timeout) as cam, \
            Progress("[progress.description]{task.description}", BarColumn(), DownloadColumn(),
                     TransferSpeedColumn(), console=console) as bar:
        before = cam.info().firmware_version
        task = bar.add_task(f"{cam.info().serial}: {before} → {inspect_image(image).build.version}", total=len(image))
        result = cam.update_firmware(image, progress=lambda done, total: bar.update(task, completed=done),
                                     replace=args.replace)
    resumed = f", resumed at byte {result.resumed_from}" if result.resumed_from else ""
    print(f"updated {args.url}: {before} -> {result.version} in slot {result.slot}, confirmed; "
          f"slot hash {result.sha256}{resumed} ({result.seconds:.2f} s)")
    return 0


def status(args: argparse.Namespace) -> int:
    with stereocam.open(args.url, timeout=args.timeout) as cam:
        st = cam.firmware_status()
    if args.json:
        print(json.dumps({"url": args.url, "running": st.running, "mode": st.mode.name.lower(),
                          "security_counter": st.security_counter,
                          "transfer": {"received": st.transfer[0], "size": st.transfer[1]},
                          "slots": [{"slot": s.slot, "version": s.version, "state": s.state.name.lower(),
                                     "confirmed": s.confirmed, "security_counter": s.security_counter,
                                     "sha256": s.sha256} for s in st.slots]}, indent=2))
        return 0
    table = Table(title=f"{args.url}: running {st.running} ({st.mode.name.lower()}), "
                        f"minimum security counter {st.security_counter}")
    for col in ("slot", "version", "state", "confirmed", "security counter", "sha256"):
        table.add_column(col, overflow="fold")
    for s in st.slots:
        table.add_row(s.slot, s.version or "-", s.state.name.lower(), "yes" if s.confirmed else "no",
                      str(s.security_counter), s.sha256)
    Console().print(table)
    if st.transfer[1]:
        print(f"transfer in progress: {st.transfer[0]} of {st.transfer[1]} bytes")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="stereocam firmware", description=__doc__.splitlines()[0].replace("``", ""),
                                 epilog=EXIT_CODES)
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("keygen", help="make an Ed25519 signing key pair")
    p.add_argument("--out", type=Path, required=True)
    p.set_defaults(run=keygen)
    p = sub.add_parser("sign", help="build a signed image from a firmware build (JSON)")
    p.add_argument("--key", type=Path, required=True)
    p.add_argument("--version", required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--security-counter", type=int, default=None,
                   help="default: the version as a number; a rollback image sets one >= the unit's")
    p.add_argument("--target", default=DEFAULT_TARGET, help="model the image is for")
    p.add_argument("--code", type=Path, default=None, help="the firmware's code (opaque bytes)")
    p.add_argument("build", type=Path)
    p.set_defaults(run=sign)
    for name, fn, text in (("update", update, "install a signed image"), ("status", status, "show both slots")):
        p = sub.add_parser(name, help=text)
        p.add_argument("url")
        if name == "update":
            p.add_argument("image", type=Path)
            p.add_argument("--replace", action="store_true", help="abandon another image's transfer in progress")
        else:
            p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
        p.add_argument("--timeout", type=float, default=2.0)
        p.set_defaults(run=fn)
    args = ap.parse_args(argv)
    return args.run(args)
