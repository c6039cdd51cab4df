"""TRIGGER, START, STOP (SPEC §4.4–§4.6) and pulses on the external trigger input (§8.5)."""
from __future__ import annotations

import collections

from stereocam.protocol import messages as m
from stereocam.protocol.errors import ErrorCode
from stereocam.protocol.params import BY_NAME, TriggerMode

from ..link_layer.dispatcher import Handler
from ..link_layer.refusal import Refusal
from ..pipeline.capture_engine import CaptureEngine
from .config_store import ConfigStore


class StreamingHandlers:
    def __init__(self, store: ConfigStore, engine: CaptureEngine, counters: collections.Counter[str]):
        self._store = store
        self._engine = engine
        self._counters = counters
        self._soft_triggers = 0  # accepted TRIGGERs since boot: the next one's trigger id is this + 1

    def handlers(self) -> dict[int, Handler]:
        return {m.MsgType.TRIGGER: self.trigger, m.MsgType.START: self.start, m.MsgType.STOP: self.stop}

    def trigger(self, _: m.Message) -> m.Triggered:
        if self._store.snapshot()["trigger_mode"] != TriggerMode.SOFTWARE:
            raise Refusal(ErrorCode.BAD_STATE, "software trigger needs trigger_mode=software",
                          BY_NAME["trigger_mode"].pid)
        if not self._engine.streaming:
            raise Refusal(ErrorCode.BAD_STATE, "software trigger needs a started stream",
                          BY_NAME["trigger_mode"].pid)  # SPEC §4.4: both preconditions name parameter 6
        req = self._engine.trigger(self._soft_triggers + 1, TriggerMode.SOFTWARE)
        if req is None:
            raise Refusal(ErrorCode.BUSY, "trigger queue full; previous captures still pending")
        self._soft_triggers += 1
        self._counters["triggers"] += 1
        return m.Triggered(req.trigger_id, req.sequence)

    def start(self, _: m.Message) -> m.Started:
        cfg = self._store.snapshot()
        if not self._engine.streaming:
            self._engine.start(TriggerMode(cfg["trigger_mode"]), cfg["fps"])
        return m.Started()

    def stop(self, _: m.Message) -> m.Stopped:
        self._engine.stop()
        return m.Stopped()

    def on_pulse(self, trigger_id: int, at: float) -> None:
        """The trigger input fired (exposure at host-monotonic ``at``): a capture in external mode
        while streaming, else ignored."""
        if self._store.snapshot()["trigger_mode"] == TriggerMode.EXTERNAL and self._engine.streaming:
            self._counters["triggers"] += 1
            self._engine.trigger(trigger_id, TriggerMode.EXTERNAL, at)
