"""MuJoCo's process-global callbacks (passive forces, control), shared by every thread that runs a model.

`installed` registers a run's callback for its model in a table that one dispatcher serves, so runs in several
threads each get their own, and MuJoCo's own callback is back when the last run ends. MuJoCo's compiler cannot run a
Python callback (a compile fails while one is installed), so every compile goes through `compiling`, which waits
until no other thread's run has one installed. A model `attach` gave Python-backend surfaces carries a mark
(`PYTHON_MARK`): stepped while the dispatcher serves other models, it is refused rather than run without its forces.
"""

from __future__ import annotations

import contextlib
import threading
from typing import Callable, Iterator

import mujoco

from .errors import SceneError

Callback = Callable[[mujoco.MjModel, mujoco.MjData], None]


class _Table:
    """One of MuJoCo's process-global callbacks shared by every thread: while any run needs it, a dispatcher is
    installed that calls the callback registered for the model being stepped (a model without one gets what was
    installed before, or nothing). A model runs one callback at a time; stepping a model with another thread's
    callback would mix their forces, so the second is refused. MuJoCo's compiler cannot run Python callbacks (any
    compile fails while one is installed): `compiling` waits until no run has one."""

    def __init__(self, get: Callable[[], Callback | None], put: Callable[[Callback | None], None], what: str,
                 guard: Callable[[mujoco.MjModel], str] | None = None) -> None:
        self.get, self.put, self.what, self.guard = get, put, what, guard
        self.callbacks: dict[int, tuple[Callback, int]] = {}  # model address -> (callback, owning thread)
        self.previous: Callback | None = None

    def __call__(self, m: mujoco.MjModel, d: mujoco.MjData) -> None:
        entry = self.callbacks.get(m._address)
        if entry is not None:
            if m._address in _failed:
                return
            try:
                entry[0](m, d)
            except BaseException as exc:
                # An exception that reaches MuJoCo's C code from a native stepper ends the interpreter (a fatal
                # error): kept, the model's callbacks skipped, and raised by `check` when the stepper returns.
                # MuJoCo's bindings raise it themselves from their own mj_step (a user's step in a block).
                if not getattr(_deferring, "on", False):
                    raise
                _failed[m._address] = exc
            return
        reason = "" if self.guard is None else self.guard(m)
        if reason:
            raise SceneError(reason)
        if self.previous is not None:
            self.previous(m, d)

    @contextlib.contextmanager
    def installed(self, model: mujoco.MjModel, callback: Callback) -> Iterator[None]:
        key, me = model._address, threading.get_ident()
        with _STATE:
            _STATE.wait_for(lambda: not _STATE.compiling)
            owner = self.callbacks.get(key)
            if owner is not None and owner[1] != me:
                raise SceneError(f"the model is already running in another thread with the Python backend's "
                                 f"{self.what} callback: give each thread a model of its own (compile it again)")
            if not self.callbacks:
                self.previous = self.get()
                self.put(self)
            self.callbacks[key] = (callback, me)
        try:
            yield
            check(model)
        finally:
            _failed.pop(key, None)
            with _STATE:
                if owner is None:
                    del self.callbacks[key]
                else:
                    self.callbacks[key] = owner
                if not self.callbacks:
                    self.put(self.previous)
                    self.previous = None
                _STATE.notify_all()


# The exception a model's callback raised (model address -> exception), until `check` raises it.
_failed: dict[int, BaseException] = {}
# Whether this thread's steps run from finrft's native steppers (`deferred`).
_deferring = threading.local()


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A block whose steps run from finrft's native steppers, through C that cannot carry a Python exception: a
    callback's exception is kept and raised by `check` after each call."""
    _deferring.on = True
    try:
        yield
    finally:
        _deferring.on = False


def check(model: mujoco.MjModel) -> None:
    """Raise the exception a callback of ``model`` raised while MuJoCo stepped it, if any: after every call that
    steps it from C (MuJoCo's bindings raise it themselves only from their own mj_step)."""
    failure = _failed.pop(model._address, None)
    if failure is not None:
        raise failure


class _State(threading.Condition):
    compiling = 0


_STATE = _State()


def python_backend_reason(m: mujoco.MjModel) -> str:
    """Why a model may not be stepped without its Python callback: it was compiled from a spec `attach` gave
    Python-backend surfaces (marked by a text element), or ""."""
    if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_TEXT, PYTHON_MARK) < 0:
        return ""
    return ("a model with Python-backend RFT (attach(..., backend='python')) is being stepped outside its own "
            "Attached.installed(model) block: step it inside that block, or attach with backend='native'")


# The text element `attach` adds to a spec it gives Python-backend surfaces.
PYTHON_MARK = "finrft.python_backend"

_PASSIVE = _Table(mujoco.get_mjcb_passive, mujoco.set_mjcb_passive, "passive-force", python_backend_reason)
_CONTROL = _Table(mujoco.get_mjcb_control, mujoco.set_mjcb_control, "control")


def installed(model: mujoco.MjModel, callback: Callback | None) -> contextlib.AbstractContextManager[None]:
    """MuJoCo applies ``callback`` as the passive-force callback of ``model`` for a block (None: nothing to
    install); other threads may run other models with their own meanwhile, and MuJoCo's own callback is restored
    when the last block ends."""
    return contextlib.nullcontext() if callback is None else _PASSIVE.installed(model, callback)


def controlled(model: mujoco.MjModel, callback: Callback | None) -> contextlib.AbstractContextManager[None]:
    """MuJoCo calls ``callback`` as the control callback of ``model`` for a block (in every step and mj_forward,
    after the velocities and before the actuation: the place to set ``ctrl`` and ``qfrc_applied`` from the time
    and state), as `installed` does the passive one; None installs nothing."""
    return contextlib.nullcontext() if callback is None else _CONTROL.installed(model, callback)


@contextlib.contextmanager
def compiling() -> Iterator[None]:
    """A block in which MuJoCo may compile: it waits until no run of another thread has a Python callback
    installed (MuJoCo's compiler fails with one), and holds new ones back until it ends."""
    me = threading.get_ident()
    with _STATE:
        mine = [t for t in (_PASSIVE, _CONTROL) for _, owner in t.callbacks.values() if owner == me]
        if mine:
            raise SceneError("a model cannot be compiled inside a block that runs another with a Python callback "
                             "(MuJoCo's compiler cannot run it): compile every model first")
        _STATE.wait_for(lambda: not (_PASSIVE.callbacks or _CONTROL.callbacks))
        _STATE.compiling += 1
    try:
        yield
    finally:
        with _STATE:
            _STATE.compiling -= 1
            _STATE.notify_all()
