"""A Camera's configuration: parameters by name, the trigger mode and presets."""
from __future__ import annotations

import os
from typing import TYPE_CHECKING

from stereocam.protocol import messages as m
from stereocam.protocol.config_rules import merge
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_ID, PARAMS, Param, TriggerMode

from . import presets
from .arguments import config_update
from .connection import Connection
from .device_types import config_names


class CameraSettings:
    """Camera's configuration side (a mixin). ``_applied`` holds every parameter this Camera set,
    which ``Camera.reconnect`` applies again; Camera sets the attributes below."""

    connection: Connection
    _applied: dict[str, int]
    _streaming: bool

    if TYPE_CHECKING:
        def request(self, msg: m.Message, timeout: float | None = None) -> m.Message: ...

    @staticmethod
    def options() -> list[Param]:
        """Every parameter: name, range (lo..hi, step, odd), unit, default, description, live."""
        return list(PARAMS)

    def config(self) -> dict[str, int]:
        r = self.request(m.GetConfig())
        assert isinstance(r, m.Config)
        return config_names(r.values)

    def configure(self, **params: int) -> dict[str, int]:
        """Change parameters by name (protocol/params.py); returns the whole new configuration.

        All or nothing: the device checks the whole set and a refusal changes nothing.
        """
        update = config_update(params)
        r = self.request(m.SetConfig(update))
        assert isinstance(r, m.ConfigApplied)
        self._applied.update({BY_ID[k].name: v for k, v in update.items()})
        return config_names(r.values)

    def check_config(self, **params: int) -> dict[str, int]:
        """The configuration ``configure(**params)`` would give, checked here against the
        protocol's rules (protocol/config_rules.py) without changing the device; ConfigRejected
        (a ConfigError naming the parameter, ``.param``, and the NACK code) if the device would
        refuse it (also a value needing a capability this device does not advertise, or a format
        beyond the selected matcher's INFO stage limit). The device stays the authority:
        ``configure`` still sends the request."""
        info = self.connection.info
        limits = {m.Stage.BLOCK_MATCHING: info.stage_limit(m.Stage.BLOCK_MATCHING),
                  m.Stage.SEMI_GLOBAL: info.stage_limit(m.Stage.SEMI_GLOBAL)}
        return merge(self.config(), config_update(params), self._streaming, info.effective_capabilities, limits)

    def set_trigger_mode(self, mode: TriggerMode | str) -> None:
        """``mode``: a TriggerMode, its name ("free_run", "software", "external") or its number."""
        if isinstance(mode, str):
            try:
                mode = TriggerMode[mode.upper().replace("-", "_")]
            except KeyError as exc:
                raise ConfigError(f"unknown trigger mode {mode!r}; known: free_run, software, external") from exc
        if isinstance(mode, int) and not isinstance(mode, (bool, TriggerMode)) and mode in set(TriggerMode):
            mode = TriggerMode(mode)
        if not isinstance(mode, TriggerMode):
            raise ConfigError(f"trigger mode must be a TriggerMode, its name or its number, got {mode!r}")
        self.configure(trigger_mode=int(mode))

    def save_preset(self, path: str | os.PathLike) -> dict[str, int]:
        """Write the whole current configuration to ``path`` as JSON; returns it."""
        config = self.config()
        presets.write_preset(path, config, self.connection.info.model)
        return config

    def load_preset(self, preset: str | os.PathLike) -> dict[str, int]:
        """Apply a named preset ('high_density', 'high_accuracy', 'off': the values it names) or one
        written by ``save_preset`` (all or nothing: a refusal changes nothing); returns the new
        configuration. ConfigError for a file that is not a preset."""
        return self.configure(**presets.preset_values(preset))
