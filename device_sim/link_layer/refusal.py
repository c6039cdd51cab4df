"""The firmware's one way to refuse a request: raise ``Refusal``; the dispatcher NACKs it."""
from __future__ import annotations

from stereocam.protocol.config_rules import ConfigRejected
from stereocam.protocol.errors import ErrorCode


class Refusal(Exception):
    """A request the device will not carry out; the state it guards is unchanged (SPEC §6)."""

    def __init__(self, code: ErrorCode, message: str, param_id: int = 0):
        super().__init__(message)
        self.code = code
        self.message = message
        self.param_id = param_id

    @classmethod
    def from_config(cls, exc: ConfigRejected) -> "Refusal":
        return cls(exc.code, str(exc), exc.param_id)
