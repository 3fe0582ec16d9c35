"""Interrupts (Ctrl-C; on the command line SIGTERM and SIGHUP too) raised only where finrft can stop cleanly.

Python runs a signal's handler between two bytecodes of the main thread, anywhere, and a KeyboardInterrupt raised
inside MuJoCo's bindings does harm: raised in a callback that MuJoCo's C code called (a native stepper) it is a
fatal error that ends the interpreter, raised while pybind11 converts an argument it becomes a TypeError. Inside a
`deferred` block (every run) a signal only marks itself, and `check`, at every event of a run, raises it as an
`Interrupt`. A handler cannot run at all while the main thread is inside one long C call (compiling a huge model):
on the command line `watched` then ends the process itself, GRACE seconds after the signal.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from typing import Any, Callable, Iterator

# How long (s) the command line waits for Python to raise a signal before it ends the process itself.
GRACE = 0.25


class Interrupt(KeyboardInterrupt):
    """A signal raised where finrft could stop; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__()
        self.signum = signum


# pending: a signal marked inside a deferred block, not yet raised; depth: nested deferred blocks (main thread);
# last: the last signal received; raised: how many were raised to Python; watched: inside `watched`.
_state = {"pending": 0, "depth": 0, "last": 0, "raised": 0, "watched": 0}


def handler(signum: int, frame: object) -> None:
    """The signal handler: raise at once, or inside a `deferred` block only mark the signal for `check`."""
    _state["last"] = signum
    if _state["depth"]:
        _state["pending"] = _state["pending"] or signum
        return
    _raise(signum)


def _raise(signum: int) -> None:
    # Under `watched` a signal stays pending once raised: a KeyboardInterrupt raised in a finaliser or a weakref's
    # callback is printed and dropped by Python, and the next `check` raises it again.
    _state["pending"] = signum if _state["watched"] else 0
    _state["raised"] += 1
    raise Interrupt(signum)


def check() -> None:
    """Raise the signal a `deferred` block marked, if any: where the caller can stop cleanly."""
    if _state["pending"]:
        _raise(_state["pending"])


def received() -> int:
    """The last signal the handler received (SIGINT where none did: a KeyboardInterrupt of Python's own)."""
    return _state["last"] or int(signal.SIGINT)


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Signals inside the block are raised by `check` only, or when the block ends. Python's own Ctrl-C handler
    is replaced by `handler` for the block; other threads (which receive no signals) are left as they are."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    own = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if own:
        signal.signal(signal.SIGINT, handler)
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
        if own:
            signal.signal(signal.SIGINT, signal.default_int_handler)
        if not _state["depth"]:
            check()


SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


@contextlib.contextmanager
def watched(on_timeout: Callable[[int], None]) -> Iterator[None]:
    """The command line's signals (SIGINT, SIGTERM, SIGHUP) go to `handler` in the block, and a thread watches
    them: when Python has not raised one GRACE seconds after it came (the main thread is in a long C call),
    ``on_timeout(signum)`` runs and the process ends with status 128 + signum. Former handlers are restored after
    the block. Outside the main thread (no handlers there) it does nothing."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "set_wakeup_fd"):
        yield
        return
    _state.update(last=0, pending=0, watched=1)
    unraisable = sys.unraisablehook

    def dropped(info: Any) -> None:  # an interrupt a finaliser dropped is raised again by `check`: no traceback
        if not isinstance(info.exc_value, Interrupt):
            unraisable(info)

    sys.unraisablehook = dropped
    reader, writer = os.pipe()
    os.set_blocking(writer, False)
    _state["depth"] += 1  # a signal while the handlers and the watcher are set up is raised once the block begins
    before = {number: signal.signal(number, handler) for number in SIGNALS}
    wakeup = signal.set_wakeup_fd(writer, warn_on_full_buffer=False)
    done = threading.Event()

    def watch() -> None:
        # Every signal that came is raised once, but for a second one while the first is pending: then the
        # process ends here too (a second Ctrl-C forces the end).
        came, raised = 0, _state["raised"]
        while True:
            data = os.read(reader, 64)
            if done.is_set() or not data:
                return
            for signum in (b for b in data if b in SIGNALS):
                came += 1
                if done.wait(GRACE):
                    return
                if _state["raised"] - raised < came:
                    on_timeout(signum)
                    os._exit(128 + signum)

    thread = threading.Thread(target=watch, name="finrft-signal-watch", daemon=True)
    thread.start()
    try:
        _state["depth"] -= 1
        check()
        yield
    finally:
        done.set()
        _state.update(pending=0, watched=0)
        sys.unraisablehook = unraisable
        signal.set_wakeup_fd(wakeup)
        for number, former in before.items():
            signal.signal(number, former)
        os.write(writer, b"\0")
        thread.join()
        os.close(reader)
        os.close(writer)
