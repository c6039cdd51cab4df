"""The device's configuration store: validated, all-or-nothing updates (rules: protocol/config_rules.py)."""
from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping

from stereocam.protocol.config_rules import ConfigRejected, StageLimits, merge
from stereocam.protocol.params import PARAMS, defaults

from ..link_layer.refusal import Refusal


class ConfigStore:
    """Current configuration by name; ``apply`` checks a whole update before changing anything."""

    def __init__(self) -> None:
        self._values = defaults()
        self._capabilities: int | None = None
        self._stage_limits: StageLimits | None = None
        self._lock = threading.Lock()

    def reset(self, values: dict[str, int], capabilities: int | None = None,
              stage_limits: StageLimits | None = None) -> None:
        """Boot: every parameter back to ``values`` (the booted build's defaults); values that need
        a capability (SPEC §5.1) are refused unless ``capabilities`` (the build's) has it, formats
        beyond the selected matcher's ``stage_limits`` (SPEC §5.2 rule 8) always."""
        with self._lock:
            self._values = {**defaults(), **values}
            self._capabilities = capabilities
            self._stage_limits = stage_limits

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return dict(self._values)

    def by_id(self) -> dict[int, int]:
        snap = self.snapshot()
        return {p.pid: snap[p.name] for p in PARAMS}

    def apply(self, update: Mapping[int, int] | Iterable[tuple[int, int]], streaming: bool) -> None:
        """Apply ``update`` (wire id → value, or SET_CONFIG's entries in payload order) atomically; a
        Refusal leaves the store as it was."""
        with self._lock:
            try:
                self._values = merge(self._values, update, streaming, self._capabilities, self._stage_limits)
            except ConfigRejected as exc:
                raise Refusal.from_config(exc) from exc
