"""Signed firmware images (SPEC §14.1): header, payload (the firmware build + its code), Ed25519 signature.

Layout, little-endian (an MCUboot-like header with the signature as a fixed trailer):

    off size field
    0   4    magic b"SCFW"
    4   2    header version (= 1)
    6   2    header length (= 80)
    8   4    payload size n
    12  4    security counter (downgrade protection: a unit refuses a lower one than it confirmed)
    16  1,1,2 image version major, minor, patch
    20  16   load target: the model the image is built for (ASCII, NUL padded)
    36  1    hash algorithm (1 = SHA-256)
    37  3    reserved (0)
    40  8    signing key id: first 8 bytes of SHA-256 of the raw Ed25519 public key
    48  32   SHA-256 of the payload
    80  n    payload: u32 build length, the build (UTF-8 JSON), the code (opaque bytes)
    80+n 64  Ed25519 signature over bytes [0, 80+n)

An image without the 64 signature bytes is *unsigned* and refused like any other bad image.
The same module parses and verifies on the host (``stereocam firmware sign``) and in the unit.
"""
from __future__ import annotations

import enum
import hashlib
import json
import math
import re
import struct
from dataclasses import dataclass, field

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import serialization
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey

from .errors import StereoCamError
from .params import BY_NAME, INT32_MAX, INT32_MIN

MAGIC = b"SCFW"
HEADER_VERSION = 1
HASH_SHA256 = 1
SIGNATURE_LEN = 64
_HEADER = struct.Struct("<4sHHIIBBH16sB3x8s32s")
HEADER_LEN = _HEADER.size
_BUILD_LEN = struct.Struct("<I")
TARGET_LEN = 16  # bytes of the header's load target field
U32_MAX = 2**32 - 1  # the header's security counter and INFO.capabilities are u32
U8_MAX = 255  # INFO carries the protocol minor version as one byte
MAX_IMAGE_BYTES = 4 << 20  # no image slot of a STOC-class unit is larger (8 MiB flash, two slots)
MAX_KEY_BYTES = 64 << 10  # a PEM Ed25519 key is a few hundred bytes
VERSION_MAX_BYTES = 255  # INFO and SLOT_INFO carry the version as a u8-length UTF-8 string
_VERSION = re.compile(r"([0-9]+)\.([0-9]+)\.([0-9]+)(\+.*)?", re.DOTALL)


class ImageFault(enum.IntEnum):
    """Why an image is refused; a NACK IMAGE_REJECTED text starts with its lower-case name (SPEC §14.4)."""

    MALFORMED = 1  # bad magic, header or build
    TRUNCATED = 2
    UNSIGNED = 3
    WRONG_KEY = 4  # signed, but not by the key the unit trusts
    TAMPERED = 5  # payload hash or signature does not match the bytes
    WRONG_TARGET = 6
    ROLLBACK = 7  # security counter below the one the unit has confirmed
    HASH_MISMATCH = 8  # the bytes received are not the ones UPDATE_BEGIN announced


class ImageError(StereoCamError, ValueError):
    """An image (or build, or key file) that cannot be used; ``fault`` says why."""

    def __init__(self, fault: ImageFault, message: str):
        super().__init__(f"{fault.name.lower()}: {message}")
        self.fault = fault


@dataclass(frozen=True)
class FirmwareBuild:
    """What a firmware build is: the unit reports and behaves as its booted build says."""

    version: str
    protocol_minor: int
    capabilities: int
    parameter_defaults: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> bytes:
        return json.dumps({"version": self.version, "protocol_minor": self.protocol_minor,
                           "capabilities": self.capabilities, "parameter_defaults": self.parameter_defaults},
                          sort_keys=True).encode()

    @classmethod
    def from_json(cls, data: bytes) -> "FirmwareBuild":
        """The build a JSON object describes; ImageError (MALFORMED, naming the field) for anything a
        unit could not report or apply: a non-integer or out-of-range number, a bad version string."""
        try:
            d = json.loads(data)
        except (ValueError, TypeError) as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
            raise ImageError(ImageFault.MALFORMED, f"not a firmware build: {exc}") from exc
        if not isinstance(d, dict):
            raise ImageError(ImageFault.MALFORMED, f"not a firmware build: a JSON object is needed, not "
                                                   f"{type(d).__name__}")
        missing = [k for k in ("version", "protocol_minor", "capabilities") if k not in d]
        if missing:
            raise ImageError(ImageFault.MALFORMED, f"not a firmware build: missing {', '.join(missing)}")
        defaults = d.get("parameter_defaults", {})
        if not isinstance(defaults, dict):
            raise ImageError(ImageFault.MALFORMED, "parameter_defaults must be a JSON object of name: integer")
        build = cls(d["version"], d["protocol_minor"], d["capabilities"], dict(defaults))
        build.check()
        return build

    def check(self) -> None:
        """ImageError (MALFORMED, naming the field) unless every field fits what a unit reports and applies."""
        if not isinstance(self.version, str):
            raise ImageError(ImageFault.MALFORMED, f"version must be a string, not {_shown(self.version)}")
        parse_version(self.version)
        _check_int("protocol_minor", self.protocol_minor, 0, U8_MAX)
        _check_int("capabilities", self.capabilities, 0, U32_MAX)
        for name, value in self.parameter_defaults.items():
            what = f"parameter default {name!r}"
            _check_int(what, value, INT32_MIN, INT32_MAX)
            if name in BY_NAME and (why := BY_NAME[name].check(value)) is not None:
                raise ImageError(ImageFault.MALFORMED, f"{what}: {why}")


def _shown(value: object) -> str:
    """A value for an error message, cut short (a hostile build may hold anything)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _check_int(field_name: str, value: object, lo: int, hi: int) -> None:
    """ImageError (MALFORMED) unless ``value`` is an integer (not a bool, not a float) in lo..hi."""
    if isinstance(value, bool) or not isinstance(value, int):
        kind = "not a finite number" if isinstance(value, float) and not math.isfinite(value) else \
            type(value).__name__
        raise ImageError(ImageFault.MALFORMED, f"{field_name} must be an integer in {lo}..{hi}, got "
                                               f"{_shown(value)} ({kind})")
    if not lo <= value <= hi:
        raise ImageError(ImageFault.MALFORMED, f"{field_name} must be in {lo}..{hi}, got {_shown(value)}")


def parse_version(text: str) -> tuple[int, int, int]:
    """"1.2.3" (or "1.2.3+BUILD") → (1, 2, 3); ImageError (MALFORMED) for anything else."""
    match = _VERSION.fullmatch(text) if isinstance(text, str) else None
    if match is None:
        raise ImageError(ImageFault.MALFORMED, f"version {_shown(text)} is not MAJOR.MINOR.PATCH")
    try:
        encoded = text.encode("utf-8")
    except UnicodeEncodeError as exc:  # a lone surrogate from a JSON "\udxxx" escape
        raise ImageError(ImageFault.MALFORMED, f"version {_shown(text)} is not valid UTF-8 text") from exc
    if len(encoded) > VERSION_MAX_BYTES:
        raise ImageError(ImageFault.MALFORMED, f"version {_shown(text)} is longer than {VERSION_MAX_BYTES} bytes "
                                               "(what INFO carries)")
    major, minor, patch = (int(g) for g in match.groups()[:3])
    if not (0 <= major < 256 and 0 <= minor < 256 and 0 <= patch < 65536):
        raise ImageError(ImageFault.MALFORMED, f"version {text!r} out of range")
    return major, minor, patch


def auto_security_counter(version: str) -> int:
    """The default security counter: the version as one number (a rollback image sets its own)."""
    major, minor, patch = parse_version(version)
    return major << 24 | minor << 16 | patch


def key_id(public_key: Ed25519PublicKey) -> bytes:
    raw = public_key.public_bytes(serialization.Encoding.Raw, serialization.PublicFormat.Raw)
    return hashlib.sha256(raw).digest()[:8]


@dataclass(frozen=True)
class FirmwareImage:
    """A parsed image: header fields, the build it carries, and its SHA-256 (of the whole image)."""

    security_counter: int
    version: tuple[int, int, int]
    target: str
    key_id: bytes
    build: FirmwareBuild
    code_size: int
    size: int
    sha256: bytes


def build_image(build: FirmwareBuild, key: Ed25519PrivateKey | None, *, target: str,
                security_counter: int | None = None, code: bytes = b"") -> bytes:
    """The image bytes; ``key`` None gives an unsigned image (for tests of the refusal)."""
    counter = auto_security_counter(build.version) if security_counter is None else security_counter
    _check_int("security counter", counter, 0, U32_MAX)
    check_target(target)
    body = build.to_json()
    payload = _BUILD_LEN.pack(len(body)) + body + code
    kid = key_id(key.public_key()) if key is not None else bytes(8)
    header = _HEADER.pack(MAGIC, HEADER_VERSION, HEADER_LEN, len(payload), counter, *parse_version(build.version),
                          target.encode("ascii"), HASH_SHA256, kid, hashlib.sha256(payload).digest())
    signed = header + payload
    return signed + key.sign(signed) if key is not None else signed


def check_target(target: str) -> None:
    """ImageError (MALFORMED) unless ``target`` fits the header's load target field whole: 1 to
    TARGET_LEN printable ASCII characters (a unit compares it with its model, byte for byte)."""
    if not isinstance(target, str) or not target or not all(" " <= c <= "~" for c in target):
        raise ImageError(ImageFault.MALFORMED, f"target {_shown(target)} must be 1 to {TARGET_LEN} printable "
                                               "ASCII characters (the image header's target field)")
    if len(target) > TARGET_LEN:
        raise ImageError(ImageFault.MALFORMED, f"target {_shown(target)} is {len(target)} characters; the image "
                                               f"header's target field holds at most {TARGET_LEN}")


def parse_header(data: bytes) -> tuple[int, int, tuple[int, int, int], str, bytes, bytes]:
    """(payload size, security counter, version, target, key id, payload hash) from the first bytes."""
    if len(data) < HEADER_LEN:
        raise ImageError(ImageFault.TRUNCATED, f"{len(data)} bytes, a header alone is {HEADER_LEN}")
    magic, hver, hlen, size, counter, major, minor, patch, target, algo, kid, digest = _HEADER.unpack_from(data)
    if magic != MAGIC or hver != HEADER_VERSION or hlen != HEADER_LEN or algo != HASH_SHA256:
        raise ImageError(ImageFault.MALFORMED, "not a stereocam firmware image (magic, header version or hash "
                                               "algorithm)")
    return size, counter, (major, minor, patch), target.rstrip(b"\0").decode("ascii", "replace"), kid, digest


def check_length(total: int, payload_size: int) -> None:
    """TRUNCATED / UNSIGNED / MALFORMED for an image of ``total`` bytes whose header says ``payload_size``."""
    signed_len = HEADER_LEN + payload_size
    if total == signed_len:
        raise ImageError(ImageFault.UNSIGNED, "the image carries no signature")
    if total < signed_len + SIGNATURE_LEN:
        raise ImageError(ImageFault.TRUNCATED, f"{total} bytes, the header announces {signed_len + SIGNATURE_LEN}")
    if total > signed_len + SIGNATURE_LEN:
        raise ImageError(ImageFault.MALFORMED, f"{total - signed_len - SIGNATURE_LEN} bytes after the signature")


def verify_image(data: bytes, trusted: Ed25519PublicKey, target: str, min_counter: int = 0) -> FirmwareImage:
    """The parsed image if it is whole, signed by ``trusted``, built for ``target`` and not a rollback."""
    size, counter, _, img_target, kid, digest = parse_header(data)
    check_length(len(data), size)
    if img_target != target:
        raise ImageError(ImageFault.WRONG_TARGET, f"built for {img_target!r}, this unit is {target!r}")
    if kid != key_id(trusted):
        raise ImageError(ImageFault.WRONG_KEY, f"signed by key {kid.hex()}, the unit trusts {key_id(trusted).hex()}")
    signed = data[:HEADER_LEN + size]
    if hashlib.sha256(signed[HEADER_LEN:]).digest() != digest:
        raise ImageError(ImageFault.TAMPERED, "the payload does not match its hash")
    try:
        trusted.verify(data[HEADER_LEN + size:], signed)
    except InvalidSignature as exc:
        raise ImageError(ImageFault.TAMPERED, "the signature does not verify") from exc
    if counter < min_counter:
        raise ImageError(ImageFault.ROLLBACK, f"security counter {counter} is below the unit's {min_counter}")
    return inspect_image(data)


def inspect_image(data: bytes) -> FirmwareImage:
    """The image's fields and build as its header and payload say, signature NOT checked (for hosts,
    which do not hold the unit's trusted key; the unit verifies)."""
    size, counter, version, target, kid, _ = parse_header(data)
    check_length(len(data), size)
    (blen,) = _BUILD_LEN.unpack_from(data, HEADER_LEN)
    build = FirmwareBuild.from_json(data[HEADER_LEN + 4:HEADER_LEN + 4 + blen])
    return FirmwareImage(counter, version, target, kid, build, size - 4 - blen, len(data),
                         hashlib.sha256(data).digest())


def load_private_key(pem: bytes) -> Ed25519PrivateKey:
    try:
        key = serialization.load_pem_private_key(pem, password=None)
    except (ValueError, TypeError) as exc:
        raise ImageError(ImageFault.MALFORMED, f"not a PEM private key: {exc}") from exc
    if not isinstance(key, Ed25519PrivateKey):
        raise ImageError(ImageFault.MALFORMED, "the key is not an Ed25519 key")
    return key


def private_key_pem(key: Ed25519PrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def public_key_pem(key: Ed25519PublicKey) -> bytes:
    return key.public_bytes(serialization.Encoding.PEM, serialization.PublicFormat.SubjectPublicKeyInfo)
