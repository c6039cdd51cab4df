"""The frames a Camera hands out: its ``get_frame`` queue, iteration, listeners and callbacks."""
from __future__ import annotations

import time
from typing import TYPE_CHECKING, Iterator

from stereocam.protocol.errors import (CameraTimeoutError, ConfigError, DisconnectedError, EndOfRecordingError,
                                      StereoCamError, StreamStalledError, StreamStoppedError, TransportError)

from .arguments import timeout_arg
from .callbacks import FrameCallback, FrameCallbacks
from .connection import Connection
from .dispatch import FrameDispatcher, FrameQueue, Listener
from .frames import Frame


class FrameDelivery:
    """Camera's frame side (a mixin): every frame goes through ``_dispatcher`` to each listener; the
    ``get_frame`` queue ``_frames`` is one of them, replaced by the ``on_frame`` callbacks while any
    is registered. Camera sets the attributes below; ``_streaming`` and ``_stream_error`` are its
    stream state (start, stop, the device stopping the stream on its own)."""

    url: str
    timeout: float
    auto_reconnect: bool
    connection: Connection
    _queue_depth: int
    _dispatcher: FrameDispatcher
    _frames: FrameQueue
    _callbacks: FrameCallbacks | None
    _streaming: bool
    _stream_error: StreamStoppedError | None

    if TYPE_CHECKING:
        def reconnect(self, timeout: float = 10.0, backoff: float = 0.1, expected: bool = False) -> None: ...

    def get_frame(self, timeout: float | None = None) -> Frame:
        """The next complete frame; CameraTimeoutError (a TimeoutError) if none within ``timeout``
        (finite seconds >= 0; ConfigError otherwise). ``timeout=0`` polls: a queued frame at once, or
        the error at once. EndOfRecordingError (naming the file) once a replayed recording's last frame
        has been taken. StreamStoppedError if the device stopped the stream and would not restart
        (see ``Camera._on_status``). Not streaming with no frame queued: the CameraTimeoutError
        at once, saying so (no frame would come: call ``start`` first)."""
        if self._callbacks is not None and len(self._callbacks):
            raise StereoCamError("frames go to the on_frame callbacks; remove them (cam.remove_callback) "
                                 "before calling get_frame")
        timeout = self.timeout if timeout is None else timeout_arg(timeout)
        if not self._streaming and len(self._frames) == 0 and not self.connection.closed:
            raise CameraTimeoutError(f"no frame from {self.url}: it is not streaming (call start() before "
                                     "get_frame(); no frame would come)")
        frame = self._next_frame(timeout)
        if frame is None:
            raise CameraTimeoutError(f"no frame from {self.url} within {timeout:.3g} s")
        return frame

    def try_get_frame(self) -> Frame | None:
        """A queued frame, or None at once if there is none (never waits)."""
        return self._next_frame(0.0)

    def _next_frame(self, timeout: float) -> Frame | None:
        """The next frame of the get_frame queue within ``timeout`` (a queued one first, even at 0),
        else None. No request goes to the device (a reconnect with ``auto_reconnect`` aside)."""
        deadline = time.monotonic() + timeout
        while True:
            if self._stream_error is not None:
                raise self._stream_error
            try:
                self.connection.check_alive()
            except DisconnectedError:
                if not self.auto_reconnect or self.connection.closed:
                    raise
                self.reconnect(timeout=max(deadline - time.monotonic(), 0.0))
            left = deadline - time.monotonic()
            frame = self._frames.get(min(left, 0.1) if left > 0 else 0.0)
            if frame is None and self._streaming and (path := self.connection.ended()) is not None:
                frame = self._last_of_recording(path)
            if frame is not None or left <= 0:
                return frame

    def _last_of_recording(self, path: str) -> Frame:
        """A frame still on its way from a replay that reached its end, else EndOfRecordingError: a
        round trip first (every frame sent before the reply has then been delivered)."""
        self.connection.status()
        frame = self._frames.get(0.0)
        if frame is None:
            raise EndOfRecordingError(f"{self.url}: end of recording {path} (every frame was delivered; "
                                      "?loop=1 plays it again)", path)
        return frame

    @property
    def frames(self) -> FrameQueue:
        """The get_frame queue: ``len`` is how many frames wait, ``dropped`` how many it discarded."""
        return self._frames

    def __iter__(self) -> Iterator[Frame]:
        """Frames as they come while streaming. Ends when the stream is stopped (``stop()`` from any
        thread, ``close()``) and the queued frames are taken, or when a replayed recording's last frame
        was taken; raises StreamStalledError (a CameraTimeoutError) when streaming but no frame came
        for ``timeout`` seconds."""
        if not self._streaming:
            raise StereoCamError("not streaming: call start() before iterating over the camera")
        while True:
            deadline = time.monotonic() + self.timeout
            while True:
                try:
                    frame = self._next_frame(min(0.1, max(deadline - time.monotonic(), 0.0)))
                except EndOfRecordingError:
                    return
                if frame is not None:
                    break
                if not self._streaming or self.connection.closed:
                    return
                if time.monotonic() >= deadline:
                    raise StreamStalledError(f"{self.url} is streaming but sent no frame for {self.timeout:.3g} s "
                                             "(software trigger mode waits for trigger())")
            yield frame

    def add_listener(self, listener: Listener) -> None:
        """Hand every frame from now on to ``listener.put`` too, which must not block: a FrameQueue
        (dispatch.py, its own size and drop policy), a RecordingListener, ... (python-can's Notifier)."""
        if not callable(getattr(listener, "put", None)):
            raise ConfigError(f"a frame listener has a put(frame) method, got {listener!r}")
        if self.connection.closed:
            raise TransportError(f"{self.url}: camera closed")
        self._dispatcher.add(listener)

    def remove_listener(self, listener: Listener) -> None:
        self._dispatcher.remove(listener)

    def on_frame(self, fn: FrameCallback) -> FrameCallback:
        """Call ``fn(frame)`` for every frame, on a thread of this Camera's (not the link's reader).
        While any callback is registered frames go to the callbacks, not to ``get_frame``. A callback
        that raises is logged and counted (``callback_errors``); ``check_callbacks()`` re-raises it.
        Registering ``fn`` again changes nothing. Returns ``fn``, so it also works as a decorator."""
        if not callable(fn):
            raise ConfigError(f"a frame callback must be callable, got {fn!r}")
        if self.connection.closed:
            raise TransportError(f"{self.url}: camera closed")
        if self._callbacks is None:
            self._callbacks = FrameCallbacks(self._queue_depth)
        self._callbacks.add(fn)
        self._dispatcher.remove(self._frames)
        self._dispatcher.add(self._callbacks)
        return fn

    def remove_callback(self, fn: FrameCallback) -> None:
        if self._callbacks is None or not self._callbacks.remove(fn):
            raise ConfigError(f"{fn!r} is not a registered frame callback")
        if not len(self._callbacks):  # frames go to get_frame again
            self._dispatcher.remove(self._callbacks)
            self._callbacks.queue.clear()
            self._dispatcher.add(self._frames)

    @property
    def callback_errors(self) -> int:
        """How many callback calls raised."""
        return 0 if self._callbacks is None else self._callbacks.errors

    def check_callbacks(self) -> None:
        """Raise CallbackError (from the callback's exception) if a frame callback has raised."""
        if self._callbacks is not None:
            self._callbacks.check()
