"""A file-backed NOR flash chip model.

Semantics (those of a SPI NOR part such as a W25Q):
  * erase_sector sets a whole sector to 0xFF;
  * program can only clear bits: new = old AND data; a byte that would need a 0→1 change is an
    error (FlashProgramError) and nothing is written;
  * one program operation covers at most one page and never crosses a page boundary;
  * a non-volatile block-protect boundary: addresses below `protected_below` cannot be erased or
    programmed (FlashProtectedError). It is kept in a sidecar file "<path>.sr" (the status
    register) and changing it counts as a step.

  * a one-time-programmable security register of `OTP_SIZE` bytes (W25Q "security register"):
    programmed like the array, never erased, and once locked (`otp_lock`) never written again.
    It is kept in "<path>.otp" (its last byte is the lock bit, 0 = locked); the firmware keeps
    the trusted firmware-signing key there.

Power loss: `power_loss_after(n)` lets n more program/erase/status steps complete; the next one
raises PowerLossError. With tear=False the file is left exactly as after the n-th step; with
tear=True the interrupted step is half done (the first half of the bytes programmed, or the first
half of the sector erased), as a real chip may leave it.
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from stereocam.protocol.errors import StereoCamError

SECTOR_SIZE = 4096
PAGE_SIZE = 256
OTP_SIZE = 256


class FlashError(StereoCamError):
    """Base of the flash model's errors."""


class FlashAddressError(FlashError, ValueError):
    """An address or length outside the chip, misaligned, or crossing a page."""


class FlashProgramError(FlashError):
    """A program operation that would need a 0→1 bit change (the sector was not erased)."""


class FlashProtectedError(FlashError):
    """An erase or program inside the write-protected range."""


class PowerLossError(FlashError):
    """Simulated power loss: the operation was cut off (see the module docstring)."""


class NorFlash:
    """NOR flash of `size` bytes stored in the file `path` (created erased if it does not exist)."""

    def __init__(self, path: str | os.PathLike[str], size: int = 64 * 1024,
                 sector_size: int = SECTOR_SIZE, page_size: int = PAGE_SIZE) -> None:
        if sector_size % page_size or size % sector_size or size <= 0:
            raise FlashAddressError(f"size {size} must be a positive multiple of sector {sector_size}, "
                                    f"itself a multiple of page {page_size}")
        self.path = Path(path)
        self.size, self.sector_size, self.page_size = size, sector_size, page_size
        self._sr_path = self.path.with_name(self.path.name + ".sr")
        if not self.path.exists():
            self.path.write_bytes(b"\xff" * size)
        elif self.path.stat().st_size != size:
            raise FlashAddressError(f"{self.path} holds {self.path.stat().st_size} bytes, expected {size}")
        self._budget: int | None = None
        self._tear = False
        self.steps = 0

    # -- power loss -------------------------------------------------------------------------
    def power_loss_after(self, n: int | None, tear: bool = False) -> None:
        """Cut the power when step n+1 starts (None: never)."""
        self._budget, self._tear = n, tear

    def _step(self) -> bool:
        """Count a step; True when power is lost during it (caller applies the torn part)."""
        if self._budget is not None:
            if self._budget <= 0:
                return True
            self._budget -= 1
        self.steps += 1
        return False

    # -- status register --------------------------------------------------------------------
    @property
    def protected_below(self) -> int:
        """Addresses below this are write-protected (0: nothing is)."""
        return struct.unpack("<I", self._sr_path.read_bytes())[0] if self._sr_path.exists() else 0

    def set_protection(self, protected_below: int) -> None:
        """Write the block-protect boundary (a sector multiple) to the status register."""
        if protected_below % self.sector_size or not 0 <= protected_below <= self.size:
            raise FlashAddressError(f"protection boundary {protected_below} is not a sector boundary")
        if self._step():
            raise PowerLossError("power lost while writing the status register")
        tmp = self._sr_path.with_name(self._sr_path.name + ".tmp")
        tmp.write_bytes(struct.pack("<I", protected_below))
        os.replace(tmp, self._sr_path)

    # -- security register (OTP) ---------------------------------------------------------------
    def _otp(self) -> bytes:
        path = self.path.with_name(self.path.name + ".otp")
        return path.read_bytes() if path.exists() else b"\xff" * (OTP_SIZE + 1)

    def otp_read(self) -> bytes:
        """The security register's contents."""
        return self._otp()[:OTP_SIZE]

    @property
    def otp_locked(self) -> bool:
        return self._otp()[OTP_SIZE] == 0

    def _otp_write(self, offset: int, data: bytes) -> None:
        old = self._otp()
        if old[OTP_SIZE] == 0:
            raise FlashProtectedError("the security register is locked")
        if self._step():
            raise PowerLossError("power lost while writing the security register")
        merged = bytes(a & b for a, b in zip(old[offset:offset + len(data)], data))
        path = self.path.with_name(self.path.name + ".otp")
        path.write_bytes(old[:offset] + merged + old[offset + len(data):])

    def otp_program(self, data: bytes) -> None:
        """Program the security register from its start (bits only clear, as in the array)."""
        if len(data) > OTP_SIZE:
            raise FlashAddressError(f"{len(data)} bytes do not fit the {OTP_SIZE}-byte security register")
        self._otp_write(0, data)

    def otp_lock(self) -> None:
        """Set the register's lock bit: it can never be written again."""
        self._otp_write(OTP_SIZE, b"\x00")

    # -- array ------------------------------------------------------------------------------
    def _check(self, addr: int, length: int) -> None:
        if addr < 0 or length < 0 or addr + length > self.size:
            raise FlashAddressError(f"range 0x{addr:x}+{length} outside the {self.size}-byte chip")
        if addr < self.protected_below:
            raise FlashProtectedError(f"address 0x{addr:x} is write-protected (below 0x{self.protected_below:x})")

    def read(self, addr: int, length: int) -> bytes:
        """Read `length` bytes at `addr`."""
        if addr < 0 or length < 0 or addr + length > self.size:
            raise FlashAddressError(f"read 0x{addr:x}+{length} outside the {self.size}-byte chip")
        with open(self.path, "rb") as f:
            f.seek(addr)
            return f.read(length)

    def _write(self, addr: int, data: bytes) -> None:
        with open(self.path, "r+b") as f:
            f.seek(addr)
            f.write(data)

    def erase_sector(self, addr: int) -> None:
        """Erase the sector starting at `addr` to 0xFF."""
        if addr % self.sector_size:
            raise FlashAddressError(f"erase address 0x{addr:x} is not sector-aligned")
        self._check(addr, self.sector_size)
        if self._step():
            if self._tear:
                self._write(addr, b"\xff" * (self.sector_size // 2))
            raise PowerLossError(f"power lost while erasing sector 0x{addr:x}")
        self._write(addr, b"\xff" * self.sector_size)

    def program(self, addr: int, data: bytes) -> None:
        """Program `data` (at most one page, not crossing a page boundary) at `addr`."""
        if not data or addr // self.page_size != (addr + len(data) - 1) // self.page_size:
            raise FlashAddressError(f"program 0x{addr:x}+{len(data)} is empty or crosses a page boundary")
        self._check(addr, len(data))
        old = np.frombuffer(self.read(addr, len(data)), dtype=np.uint8)
        new = np.frombuffer(data, dtype=np.uint8)
        bad = np.flatnonzero(new & ~old)
        if bad.size:
            raise FlashProgramError(f"program at 0x{addr + int(bad[0]):x} needs a 0->1 bit change; erase first")
        if self._step():
            if self._tear:
                half = len(data) // 2
                self._write(addr, (old[:half] & new[:half]).tobytes())
            raise PowerLossError(f"power lost while programming 0x{addr:x}+{len(data)}")
        self._write(addr, (old & new).tobytes())

    def program_range(self, addr: int, data: bytes) -> None:
        """Program `data` at `addr` as a sequence of page-sized program operations."""
        pos = 0
        while pos < len(data):
            chunk = min(len(data) - pos, self.page_size - (addr + pos) % self.page_size)
            self.program(addr + pos, data[pos:pos + chunk])
            pos += chunk
