"""Ctrl-C and SIGTERM end a live session the same way on every platform: the stream stops,
every frame received is kept.

Where the event loop handles signals itself (Unix), through it; where it cannot (Windows'
Proactor loop raises NotImplementedError, as any loop does outside the main thread), through
:func:`signal.signal`, whose handler schedules the stop on the loop thread-safely. Outside the
main thread no handler can be set; the session then ends by its other means.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import Callable, Iterator
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def stopping_on_signals(stop: Callable[[str], None]) -> Iterator[None]:
    """While inside, Ctrl-C and SIGTERM call ``stop("stopped by SIGINT")`` (or SIGTERM) on the
    running loop; the handlers before are restored on leaving."""
    loop = asyncio.get_running_loop()
    with contextlib.ExitStack() as undo:
        try:
            for sig in SIGNALS:
                loop.add_signal_handler(sig, stop, _why(sig))
                undo.callback(loop.remove_signal_handler, sig)
        except (NotImplementedError, RuntimeError):
            undo.close()                          # those the loop took before it refused
            undo.enter_context(_through_signal_module(loop, stop))
        yield


@contextlib.contextmanager
def _through_signal_module(loop: asyncio.AbstractEventLoop, stop: Callable[[str], None]
                           ) -> Iterator[None]:
    def handler(signum: int, frame: FrameType | None) -> None:
        loop.call_soon_threadsafe(stop, _why(signum))

    before = {}
    try:
        for sig in SIGNALS:
            before[sig] = signal.signal(sig, handler)
    except ValueError:                            # not the main thread: no handler at all
        pass
    try:
        yield
    finally:
        for sig, previous in before.items():
            signal.signal(sig, previous)


def _why(sig: int) -> str:
    return f"stopped by {signal.Signals(sig).name}"
