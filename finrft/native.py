"""The native RFT plugin (plugins/, built by ``pip install``): locating, checking and loading it once, and the codes
its steppers return.

MuJoCo calls `load` through the ``mujoco.plugins`` entry point whenever it is imported, in every process, and
finrft calls it again before it builds a model; loading twice is harmless. It never raises: when the library is
missing, was built for another MuJoCo, or will not load, `available` is False, finrft says so once and uses the
Python coupling instead.

setup.py reads this file on its own to name the library and its build record and to give the return codes to the
C compiler, so it imports only the standard library.
"""

from __future__ import annotations

import contextlib
import ctypes
import enum
import importlib
import re
import sys
import threading
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator

# Named as MuJoCo's own plugins are on each platform.
LIBRARY = {"win32": "finrft_rft.dll", "darwin": "libfinrft_rft.dylib"}.get(sys.platform, "libfinrft_rft.so")
PLUGIN = "finrft.rft"


class Code(enum.IntEnum):
    """What a stepper returns besides 0 (done), the native ones (FINRFT_UNSTABLE, ...) and their numpy twins."""

    UNSTABLE = 1        # the state stopped being finite
    STEP_TOO_SMALL = 2  # the adaptive step fell below 1e-9 s
    NOT_CONVERGED = 3   # Newton's method found no root, even at the smallest step
    ARENA_FULL = 4      # the native step's workspace does not fit on the mjData stack


_status: dict[str, object] = {"loaded": None, "error": "", "advice": "", "warned": False}
# untimed(): how many blocks are inside it, and the timer to put back when the last one leaves.
_timer: dict[str, object] = {"depth": 0, "saved": None, "swap": None}
_timer_lock = threading.Lock()


def library_path() -> Path:
    return Path(__file__).with_name(LIBRARY)


def built_for() -> int:
    """The MuJoCo header version (mjVERSION_HEADER) the library was compiled against, read from the file: loading
    it to ask would already bind it to the installed MuJoCo."""
    found = re.search(rb"finrft_mujoco_header=(\d+)", library_path().read_bytes())
    if found is None:
        raise OSError(f"{library_path()} does not say which MuJoCo it was built for: reinstall finrft to rebuild it")
    return int(found.group(1))


def version_text(version: int) -> str:
    """MuJoCo's version number as text: 4002001 -> 4.2.1 (SUPERMAJOR * 1e6 + MAJOR * 1e3 + MINOR_OR_PATCH)."""
    return f"{version // 1_000_000}.{version // 1000 % 1000}.{version % 1000}"


def _mujoco():
    # While `import mujoco` runs `load`, importing mujoco would be circular: use what is loaded.
    return sys.modules.get("mujoco") or importlib.import_module("mujoco")


@contextlib.contextmanager
def captured_warnings(messages: list[str]) -> Iterator[None]:
    """Collect MuJoCo's warnings, which would otherwise go to stdout and to MUJOCO_LOG.TXT in the working
    directory, so that an error can quote them."""
    mujoco = _mujoco()
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def function(name: str, restype: Any, *argtypes: Any) -> Callable[..., Any]:
    """A function of the native library (the handle MuJoCo has loaded) with its C signature; ctypes releases the
    GIL while it runs."""
    found = getattr(ctypes.CDLL(str(library_path())), name)
    found.restype, found.argtypes = restype, list(argtypes)
    return found


def _swap_timer(timer: int | None) -> int | None:
    """Set MuJoCo's timer callback (mjcb_time, a C function pointer) and return the one it had."""
    if _timer["swap"] is None:
        _timer["swap"] = function("finrft_swap_timer", ctypes.c_void_p, ctypes.c_void_p)
    return _timer["swap"](timer)


@contextlib.contextmanager
def untimed() -> Iterator[None]:
    """Step without MuJoCo's profiling timer inside the block (restored after it; blocks may nest and overlap in
    threads). MuJoCo's Python bindings install a clock (mjcb_time) that every mj_step calls about twenty times to
    fill ``MjData.timer``: a third of the step of a small model such as the plate (9.9 ms for the paper drag without
    it, 14.9 ms with it). finrft reads no timer. Some releases of the bindings put the clock back when an MjData is
    made: enter the block after making the data it steps. Without the native library (which sets the callback) the
    block changes nothing."""
    if not available():
        yield
        return
    with _timer_lock:
        previous = _swap_timer(None)
        if _timer["depth"] == 0:
            _timer["saved"] = previous
        _timer["depth"] = int(_timer["depth"]) + 1
    try:
        yield
    finally:
        with _timer_lock:
            _timer["depth"] = int(_timer["depth"]) - 1
            if _timer["depth"] == 0:
                _swap_timer(_timer["saved"])


def load() -> bool:
    """Register the plugin with MuJoCo; True when it is available."""
    if _status["loaded"] is None:
        try:
            mujoco = _mujoco()
            path = library_path()
            if not path.is_file():
                raise OSError(f"{path} does not exist (the package was installed without building it)")
            # MuJoCo may change its ABI in any release (and names its library file by version), so only the exact
            # version the plugin was compiled against can load it; checked first, as loading would fail obscurely.
            built, installed = built_for(), mujoco.mj_version()
            if built != installed:
                _status.update(loaded=False, advice=" (reinstall finrft to rebuild it)",
                               error=f"the native RFT plugin was built for MuJoCo {version_text(built)} but MuJoCo "
                                     f"{version_text(installed)} is installed")
                return False
            loader = getattr(mujoco, "mj_loadPluginLibrary", None)
            messages: list[str] = []
            with captured_warnings(messages):  # from 4.0.1 MuJoCo warns, not raises, when a library will not load
                if loader is not None:
                    loader(str(path))
                else:
                    ctypes.CDLL(str(path))  # its constructor registers the plugin
            if messages:
                raise OSError(messages[0].strip())
            _status["loaded"] = True
        except Exception as exc:  # a broken plugin must never break `import mujoco`
            _status.update(loaded=False, error=f"the native RFT plugin could not be loaded ({exc})")
    return bool(_status["loaded"])


def available() -> bool:
    return load()


def resolve_backend(requested: str) -> str:
    """The backend a run will use: ``native`` falls back to ``python`` (with one warning) when unavailable."""
    if requested == "native" and not available():
        if not _status["warned"]:
            _status["warned"] = True
            warnings.warn(f"{_status['error']}; using the Python backend{_status['advice']}", RuntimeWarning,
                          stacklevel=2)
        return "python"
    return requested
