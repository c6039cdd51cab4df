"""GET_CONFIG → CONFIG and SET_CONFIG → CONFIG_APPLIED (SPEC §4.2, §4.3)."""
from __future__ import annotations

from stereocam.protocol import messages as m

from ..link_layer.dispatcher import Handler
from ..pipeline.capture_engine import CaptureEngine
from .config_store import ConfigStore


class ConfigHandlers:
    def __init__(self, store: ConfigStore, engine: CaptureEngine):
        self._store = store
        self._engine = engine

    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.GET_CONFIG: self.get_config, m.MsgType.SET_CONFIG: self.set_config}

    def get_config(self, _: m.Message) -> m.Config:
        return m.Config(self._store.by_id())

    def set_config(self, msg: m.SetConfig) -> m.ConfigApplied:
        self._store.apply(msg.pairs, self._engine.streaming)  # a Refusal leaves everything as it was
        self._engine.set_rate(self._store.snapshot()["fps"])
        return m.ConfigApplied(self._store.by_id())
