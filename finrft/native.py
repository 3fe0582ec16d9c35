"""The native RFT plugin (plugins/finrft_rft.c, built by ``pip install``): locating and loading it once.

MuJoCo calls `load` through the ``mujoco.plugins`` entry point whenever it is imported, in every process, and
finrft calls it again before it builds a model; loading twice is harmless. It never raises: when the library is
missing or will not load, `available` is False, finrft says so once and uses the Python coupling instead.
"""

from __future__ import annotations

import ctypes
import sys
import warnings
from pathlib import Path

LIBRARY = "libfinrft_rft.so"
PLUGIN = "finrft.rft"
_status: dict[str, object] = {"loaded": None, "error": "", "warned": False}


def library_path() -> Path:
    return Path(__file__).with_name(LIBRARY)


def load() -> bool:
    """Register the plugin with MuJoCo; True when it is available."""
    if _status["loaded"] is None:
        path = library_path()
        try:
            if not path.is_file():
                raise OSError(f"{path} does not exist (the package was installed without building it)")
            # While `import mujoco` runs this, importing mujoco here would be circular: use what is loaded.
            mujoco = sys.modules.get("mujoco")
            if mujoco is None:
                import mujoco
            loader = getattr(mujoco, "mj_loadPluginLibrary", None)
            if loader is not None:
                loader(str(path))
            else:
                ctypes.CDLL(str(path))  # its constructor registers the plugin
            _status["loaded"] = True
        except Exception as exc:  # a broken plugin must never break `import mujoco`
            _status["loaded"], _status["error"] = False, str(exc)
    return bool(_status["loaded"])


def available() -> bool:
    return load()


def resolve_backend(requested: str) -> str:
    """The backend a run will use: ``native`` falls back to ``python`` (with one warning) when unavailable."""
    if requested == "native" and not available():
        if not _status["warned"]:
            _status["warned"] = True
            warnings.warn(f"the native RFT plugin could not be loaded ({_status['error']}); using the Python "
                          f"backend", RuntimeWarning, stacklevel=2)
        return "python"
    return requested
