"""``stereocam firmware keygen|sign|update|status``: signed firmware images and field updates.

    stereocam firmware keygen --out KEY [--force]        (KEY: Ed25519 private key, KEY.pub: its public half;
                                                          an existing KEY or KEY.pub is kept unless --force)
    stereocam firmware sign --key KEY --out IMAGE BUILD.json [--version V] [--security-counter N] [--code BIN]
                            [--target MODEL]
    stereocam firmware update URL IMAGE [--replace]      (progress bar; success only once the unit runs it)
    stereocam firmware status URL                        (both slots: version, state, hash, confirmed)
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import click
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
from rich.console import Console
from rich.progress import BarColumn, DownloadColumn, Progress, TransferSpeedColumn
from rich.table import Table

import stereocam
from stereocam.input_files import read_regular
from stereocam.protocol.errors import ConfigError, InputFileError
from stereocam.protocol.firmware_image import (MAX_IMAGE_BYTES, MAX_KEY_BYTES, TARGET_LEN, U32_MAX, FirmwareBuild,
                                               ImageError, build_image, check_target, inspect_image,
                                               load_private_key, private_key_pem, public_key_pem)
from stereocam.protocol.params import BY_NAME
from stereocam.tools.exit_codes import EXIT_USAGE
from stereocam.tools.options import CONTEXT, Finite, epilog
from stereocam.tools.progress import progress_wanted

DEFAULT_TARGET = "STOC-SIM"


def _fail(command: str, message: str) -> int:
    """Say what is wrong with the input on stderr; the usage exit code."""
    print(f"stereocam firmware {command}: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def _write_whole(path: Path, data: bytes, mode: int, replace: bool = True) -> None:
    """Write ``data`` to a new file beside ``path`` (``mode`` from creation, synced), then put it in
    place in one step: renamed over ``path`` (the old file stays whole until the new one is), or,
    with ``replace=False``, linked to ``path`` (FileExistsError if something is there already)."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if replace:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)
    except OSError as exc:  # named by the file asked for, not the temporary one
        raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
    finally:
        Path(tmp).unlink(missing_ok=True)


def keygen(args: SimpleNamespace) -> int:
    """A new Ed25519 key pair: KEY (0600 from creation) and KEY.pub; an existing KEY or KEY.pub is never
    overwritten unless --force (then each is replaced whole, atomically)."""
    pub = args.out.with_name(args.out.name + ".pub")
    if not args.force:
        existing = [str(p) for p in (args.out, pub) if os.path.lexists(p)]
        if existing:
            return _fail("keygen", f"{' and '.join(existing)} already exist{'s' if len(existing) == 1 else ''}; "
                                   "refusing to overwrite a signing key (it cannot be recovered). Choose another "
                                   "--out, or pass --force to replace it")
    key = Ed25519PrivateKey.generate()
    try:
        if args.force:
            _write_whole(args.out, private_key_pem(key), 0o600)
            _write_whole(pub, public_key_pem(key.public_key()), 0o644)
        else:
            _write_whole(args.out, private_key_pem(key), 0o600, replace=False)
            try:
                _write_whole(pub, public_key_pem(key.public_key()), 0o644, replace=False)
            except BaseException:
                args.out.unlink(missing_ok=True)  # ours, just made: no key without its public half
                raise
    except FileExistsError as exc:
        return _fail("keygen", f"{exc.filename} already exists (created meanwhile); nothing was written")
    except OSError as exc:
        return _fail("keygen", f"cannot write {exc.filename or args.out}: {exc.strerror or exc}")
    print(f"wrote {args.out} (private, keep it secret) and {pub}")
    return 0


def _read(path: Path, what: str, limit: int = MAX_IMAGE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (anything else refused before reading)."""
    return read_regular(path, what=what, limit=limit)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def sign(args: SimpleNamespace) -> int:
    """A signed image of BUILD.json; a bad build, key, version, counter or target: a message and exit 2."""
    if args.security_counter is not None and not 0 <= args.security_counter <= U32_MAX:
        return _fail("sign", f"--security-counter {args.security_counter} is outside 0..{U32_MAX} "
                             "(the image header holds it as an unsigned 32-bit number)")
    try:
        check_target(args.target)
    except ImageError as exc:
        return _fail("sign", f"--target: {exc}")
    inputs = {"--key": args.key, "BUILD": args.build, **({"--code": args.code} if args.code else {})}
    for flag, path in inputs.items():
        if _same_file(args.out, path):
            return _fail("sign", f"--out {args.out} is the {flag} file; refusing to overwrite it")
    try:
        key = load_private_key(_read(args.key, "key", MAX_KEY_BYTES))
        build = FirmwareBuild.from_json(_read(args.build, "build"))
        if args.version is not None and args.version != build.version:
            return _fail("sign", f"--version {args.version} disagrees with {args.build}, whose version is "
                                 f"{build.version}: the image is what its build file says (change the file, or "
                                 "leave --version out)")
        for name in build.parameter_defaults:
            if name not in BY_NAME:
                raise ConfigError(f"parameter default {name!r}: no such parameter")
        code = _read(args.code, "code") if args.code else b""
        image = build_image(build, key, target=args.target, security_counter=args.security_counter, code=code)
    except (ImageError, ConfigError, InputFileError) as exc:
        return _fail("sign", str(exc))
    try:
        _write_whole(args.out, image, 0o644)
    except OSError as exc:
        return _fail("sign", f"cannot write {args.out}: {exc.strerror or exc}")
    print(f"wrote {args.out}: {len(image)} bytes, version {build.version}, target {args.target}")
    return 0


def update(args: SimpleNamespace) -> int:
    image = _read(args.image, "image")
    console = Console(stderr=True)
    with stereocam.open(args.url, timeout=args.timeout) as cam, \
            Progress("[progress.description]{task.description}", BarColumn(), DownloadColumn(),
                     TransferSpeedColumn(), console=console, disable=not progress_wanted()) as bar:
        before = cam.info().firmware_version
        task = bar.add_task(f"{cam.info().serial}: {before} → {inspect_image(image).build.version}", total=len(image))
        result = cam.update_firmware(image, progress=lambda done, total: bar.update(task, completed=done),
                                     replace=args.replace)
    resumed = f", resumed at byte {result.resumed_from}" if result.resumed_from else ""
    print(f"updated {args.url}: {before} -> {result.version} in slot {result.slot}, confirmed; "
          f"slot hash {result.sha256}{resumed} ({result.seconds:.2f} s)")
    return 0


def status(args: SimpleNamespace) -> int:
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


def _file_name(ctx: click.Context, param: click.Parameter, value: Path | None) -> Path | None:
    """An ``--out`` that names a file: an empty path names none (click's Path lets '' through as '.')."""
    if value is not None and not value.name:
        raise click.BadParameter("the path is empty: give the file to write")
    return value


@click.group("firmware", epilog=epilog(), context_settings=CONTEXT)
def command() -> None:
    """Signed firmware images: make a signing key, sign a build, update a camera, show its slots."""


_TIMEOUT = click.option("--timeout", type=Finite(min=0, min_open=True), default=2.0, show_default=True,
                        help="Seconds to wait for each reply.")


@command.command("keygen", epilog=epilog())
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True, callback=_file_name,
              help="The private key file KEY; its public half goes to KEY.pub.")
@click.option("--force", is_flag=True, help="Replace an existing KEY and KEY.pub (the old private key is lost for good).")
def keygen_command(**params: object) -> int:
    """Make an Ed25519 signing key pair (an existing KEY or KEY.pub is kept unless --force)."""
    return keygen(SimpleNamespace(**params))


@command.command("sign", epilog=epilog())
@click.argument("build", type=click.Path(path_type=Path))
@click.option("--key", type=click.Path(path_type=Path), required=True, help="The private key (PEM).")
@click.option("--version", default=None,
              help="The version the image must have: refused unless BUILD says the same.  [default: BUILD's version]")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True, callback=_file_name,
              help="The image file to write.")
@click.option("--security-counter", type=int, default=None,
              help="Anti-rollback counter. A unit refuses an image below the highest counter it has confirmed, and "
                   "confirming raises that floor for good: a rollback image takes the NEXT counter (the unit's, "
                   "from `firmware status`, plus 1), never a large one.  [default: the version as a number]")
@click.option("--target", default=DEFAULT_TARGET, show_default=True,
              help=f"Model the image is for (printable ASCII, at most {TARGET_LEN} characters).")
@click.option("--code", type=click.Path(path_type=Path), default=None,
              help="The firmware's code (opaque bytes).  [default: none]")
def sign_command(**params: object) -> int:
    """Build a signed image from a firmware build (BUILD: JSON; the example one ships as
    stereocam/tools/firmware/build.example.json)."""
    return sign(SimpleNamespace(**params))


@command.command("update", epilog=epilog())
@click.argument("url")
@click.argument("image", type=click.Path(path_type=Path))
@click.option("--replace", is_flag=True, help="Abandon another image's transfer in progress.")
@_TIMEOUT
def update_command(**params: object) -> int:
    """Install a signed image; succeeds only once the unit runs it (a progress bar on a terminal)."""
    return update(SimpleNamespace(**params))


@command.command("status", epilog=epilog())
@click.argument("url")
@click.option("--json", is_flag=True, help="Print one JSON object instead of a table.")
@_TIMEOUT
def status_command(**params: object) -> int:
    """Show both slots: version, state, hash, confirmed."""
    return status(SimpleNamespace(**params))
