"""Ctrl-C and SIGTERM for the `mavtune` command: one interrupt, noticed wherever it lands, never lost.

`install()` makes SIGINT and SIGTERM raise KeyboardInterrupt once and remembers that they came (`received()`),
so an interrupt that lands inside an import and surfaces as another exception is still reported as one. One
that lands in a finaliser (`__del__`, a weakref callback run by the garbage collector), where Python prints
"Exception ignored" and carries on, is delivered again in the code that runs next.
`deferred()` holds them while the run folder is being written; `time_limit()` bounds work done after one.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)
_received: list[int] = []
_first_at: list[float] = []  # time.monotonic() of the first
_again: list[int] = []  # a signal whose exception a finaliser swallowed, being delivered again
REDELIVER_S = 0.01  # how long after a swallowed interrupt it comes again: the finaliser is over by then


class TimeLimit(BaseException):
    """Raised inside a `time_limit` block whose time is up. Like KeyboardInterrupt it is no `Exception`, so code
    that carries on past its own failures (a report section that could not be drawn) cannot carry on past it."""


def received() -> bool:
    """Whether SIGINT or SIGTERM arrived since `install()`."""
    return bool(_received)


def since_first() -> float:
    """Seconds since the first SIGINT/SIGTERM arrived (0 when none has): the clock of "exit within 2 s"."""
    return time.monotonic() - _first_at[0] if _first_at else 0.0


def _interrupt(signum: int, frame: object) -> None:
    if _again:
        _again.clear()
        raise KeyboardInterrupt
    first = not _received
    if first:
        _first_at.append(time.monotonic())
    _received.append(signum)
    if first:  # a second signal while the first one is being handled is only counted
        raise KeyboardInterrupt


def install() -> None:
    """SIGINT and SIGTERM raise KeyboardInterrupt (once), in the main thread; one a finaliser swallows is raised
    again."""
    for s in SIGNALS:
        signal.signal(s, _interrupt)
    if sys.unraisablehook is not _swallowed:
        _swallowed.before = sys.unraisablehook
        sys.unraisablehook = _swallowed


def _swallowed(unraisable: Any) -> None:
    """sys.unraisablehook: an interrupt or time limit raised inside a finaliser would be printed and lost (the
    run would fly on); instead its signal comes again REDELIVER_S later, from a thread, once the finaliser is over
    (raised from here it would land in this hook, as lost)."""
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _received:
        signum = _received[0]
        if not _again:
            _again.append(signum)
    elif isinstance(unraisable.exc_value, TimeLimit):
        signum = signal.SIGALRM  # the time_limit's handler, while it is still installed, raises it again
    else:
        _swallowed.before(unraisable)
        return
    threading.Thread(target=_deliver_later, args=(signum,), name="mavtune-interrupt", daemon=True).start()


_swallowed.before = sys.unraisablehook


def _deliver_later(signum: int) -> None:
    time.sleep(REDELIVER_S)
    _thread.interrupt_main(signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class Hold:
    """SIGINT/SIGTERM held from `start()` to `release()`, which delivers the first one that came to the handler
    of before (KeyboardInterrupt, or only counted when one is already being handled). Main thread only."""

    def __init__(self) -> None:
        self.held: list[int] = []
        self._before: dict[int, Any] | None = None

    def start(self) -> None:
        if self._before is None and _main_thread():
            self._before = {s: signal.signal(s, lambda signum, frame: self.held.append(signum)) for s in SIGNALS}

    def release(self) -> None:
        if self._before is None:
            return
        for s, handler in self._before.items():
            signal.signal(s, handler)
        self._before = None
        if self.held:
            first, self.held = self.held[0], []
            signal.raise_signal(first)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM for the block (files being written stay whole); one that came is raised at its end."""
    hold = Hold()
    hold.start()
    try:
        yield
    finally:
        hold.release()


@contextmanager
def time_limit(seconds: float) -> Iterator[None]:
    """Raise TimeLimit inside the block after `seconds` of wall time (main thread only; elsewhere no limit)."""
    if not _main_thread():
        yield
        return

    def up(signum: int, frame: object) -> None:
        raise TimeLimit(f"took longer than {seconds:g} s")

    before = signal.signal(signal.SIGALRM, up)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, before)
