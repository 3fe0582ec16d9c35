"""What every file finrft reads or writes shares. A file it reads is read whole or not at all, and only a regular
file of bounded size (a device, a pipe or a huge file would read without end or exhaust memory): a file that cannot
be read, is not UTF-8 text or (TOML) is malformed raises SceneError naming it, never a traceback of the reader. A
file it writes replaces its target in one step (a failed or interrupted write never leaves a truncated file where a
complete one is expected), or with ``exclusive`` appears only where nothing is (of two concurrent writers, one
refuses); the temporary files of writers that were killed are removed by the next write to the same target. A file
a run keeps rewriting (a search's log) is `locked` while the run owns it. Every file names the versions that made
it."""

from __future__ import annotations

import contextlib
import contextvars
import errno
import io
import os
import re
import stat
import tempfile
import tomllib
import uuid
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator

from .errors import SceneError, UsageError

# The largest text file finrft reads (scenes, tables, data): far above any it ships or writes.
MAX_TEXT_BYTES = 64 * 2**20


def read_text(path: str | Path, what: str, limit: int = MAX_TEXT_BYTES) -> str:
    """A text file's contents; SceneError naming the file (as ``what``) when it cannot be read, is no regular file,
    holds more than ``limit`` bytes or is not UTF-8 text."""
    try:
        return read_bytes(path, what, limit).decode("utf-8")
    except UnicodeDecodeError:
        raise SceneError(f"{what} {path} is not a text file (UTF-8)") from None


def read_bytes(path: str | Path, what: str, limit: int) -> bytes:
    """A regular file's contents, at most ``limit`` bytes; SceneError naming the file otherwise."""
    try:
        # Non-blocking: opening a FIFO would otherwise wait for a writer that may never come.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise SceneError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    try:
        check_regular(os.fstat(fd), path, what, limit)
        with os.fdopen(fd, "rb", closefd=False) as handle:
            data = handle.read(limit + 1)
    except OSError as exc:
        raise SceneError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise SceneError(f"{what} {path} holds more than {limit} bytes: it is not one finrft reads")
    return data


def check_regular(info: os.stat_result, path: str | Path, what: str, limit: int) -> None:
    """SceneError unless ``info`` (os.stat) is a regular file of at most ``limit`` bytes."""
    if not stat.S_ISREG(info.st_mode):
        raise SceneError(f"{what} {path} is not a regular file (a device, a pipe or a folder cannot be read)")
    if info.st_size > limit:
        raise SceneError(f"{what} {path} holds {info.st_size} bytes, more than the {limit} finrft reads")


def not_a_file(path: str | Path) -> str:
    """Why ``path`` is no regular file to read, for a message: "no such file", or what is there instead."""
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        return "no such file" if exc.errno == errno.ENOENT else exc.strerror or str(exc)
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a pipe"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device")):
        if test(mode):
            return f"it is {what}, not a file"
    return "it is not a regular file"


def read_toml(text: str, origin: str) -> dict[str, Any]:
    """TOML text as a nested mapping; SceneError beginning with ``origin`` when it is malformed."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {exc}") from None


def check_target(path: Any, what: str = "", error: type[SceneError] = SceneError) -> Path:
    """``path`` as a Path where a file can be written: ``error`` (naming it, after ``what``: the flag) when it is
    no path, a directory, or in a folder that is missing or cannot be written. Whether a file is there already is
    the caller's to decide."""
    if not isinstance(path, (str, os.PathLike)):
        raise error(f"{what or 'an output file'} must be a path, got {type(path).__name__} {path!r:.60}")
    name = f"{what} {path}" if what else str(path)
    target = Path(path)
    check_folder(target.parent, name, error)
    if target.is_dir():
        raise error(f"{name} is a directory: give a file name")
    # The file is written under a longer temporary name first (`atomic_path`), which must fit the file system too.
    longest = len(os.fsencode(_temporary_name(target, 4194304)))  # Linux's largest pid
    try:
        limit = os.pathconf(target.parent, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):
        limit = 255
    if longest > limit:
        raise error(f"{name}: the file name is too long (with the temporary name it is written under first, "
                    f"{longest} bytes where the file system allows {limit}): give a shorter name")
    return target


def check_folder(folder: Path, name: str, error: type[SceneError] = SceneError) -> None:
    """``error`` starting with ``name`` unless files can be written in ``folder``."""
    if not folder.is_dir():
        raise error(f"{name}: {folder} is not a directory" if folder.exists() else
                    f"{name}: directory {folder} does not exist")
    try:  # a file made and removed, not os.access: that says yes to root, and to read-only file systems
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise error(f"{name}: cannot write in {folder}: {exc.strerror}") from None


def write_bytes(path: Path, data: bytes | memoryview) -> None:
    """Write ``data`` to a new file at ``path`` and on to the disk: OSError naming ``path`` when any of it cannot be
    written (a full disk), before the file is published."""
    with open(path, "xb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())


@contextlib.contextmanager
def hdf5_written(path: str | Path, *, exclusive: bool | None = None, **options: Any) -> Iterator[Any]:
    """An HDF5 file (h5py.File, made with ``options``) to fill in the block, written to ``path`` by `atomic_path`
    (``exclusive`` as there) when the block ends. It is built in memory and written by Python, which raises
    OSError on a failed write: HDF5's own writes, failing on a full disk, leave its file object in a state whose
    close crashes the process."""
    import h5py  # here, not at the top: `import finrft` stays light
    image = io.BytesIO()
    with h5py.File(image, "w", **options) as f:
        yield f
    with atomic_path(path, exclusive=exclusive) as tmp:
        write_bytes(tmp, image.getbuffer())


# Whether `atomic_path` may replace a file that exists, where its caller does not say: the command line's writers
# may not without --force (`keep_existing`).
_exclusive: contextvars.ContextVar[bool] = contextvars.ContextVar("finrft_exclusive_writes", default=False)


@contextlib.contextmanager
def keep_existing(keep: bool = True) -> Iterator[None]:
    """Within the block, `atomic_path` (without ``exclusive``) never replaces a file: the command line's outputs
    without --force, whose absence was checked before the run, may have been written by another run since."""
    token = _exclusive.set(keep)
    try:
        yield
    finally:
        _exclusive.reset(token)


@contextlib.contextmanager
def atomic_path(path: str | Path, *, exclusive: bool | None = None) -> Iterator[Path]:
    """A temporary path next to ``path`` that replaces it when the block succeeds and is removed when it fails.
    It keeps the target's suffix, for writers that choose the format by it (matplotlib). ``exclusive`` (default:
    as `keep_existing` says): the file appears only where nothing is, else UsageError and nothing is written."""
    target = Path(path)
    remove_stale_temporaries(target)
    # Not tempfile.mkstemp: its 0600 mode would carry over to the result; the writers create the file themselves.
    # The writer's pid in the name tells the next writer whether it still runs.
    tmp = target.with_name(_temporary_name(target, os.getpid()))
    _writing.add(tmp)
    try:
        yield tmp
        if _exclusive.get() if exclusive is None else exclusive:
            _publish_new(tmp, target)
        else:
            os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if exc.filename not in (None, str(tmp)):
            raise
        # The file asked for, not its temporary, which is gone.
        raise OSError(exc.errno, f"{exc.strerror or exc}: nothing was written", str(target)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        _writing.discard(tmp)


def _temporary_name(target: Path, pid: int) -> str:
    return f".{target.stem}.{pid}-{uuid.uuid4().hex[:12]}.tmp{target.suffix}"


# The temporary files `atomic_path` blocks are writing now.
_writing: set[Path] = set()


def remove_temporaries() -> None:
    """Remove the temporary files being written, for a process that ends without leaving its blocks (os._exit)."""
    for tmp in list(_writing):
        with contextlib.suppress(OSError):
            tmp.unlink()


def _publish_new(tmp: Path, target: Path) -> None:
    """Move ``tmp`` onto ``target`` where nothing is there (a link fails atomically on an existing name); else
    UsageError."""
    taken = UsageError(f"{target} appeared while this ran (another process wrote it): it is kept, and nothing was "
                       f"written")
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise taken from None
    except OSError:  # a file system without hard links: claim the name, then replace the empty claim
        try:
            os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            raise taken from None
        os.replace(tmp, target)
        return
    tmp.unlink()


def remove_stale_temporaries(target: Path) -> None:
    """Remove the temporary files `atomic_path` left beside ``target`` in processes that have ended (killed while
    writing); those of running ones stay."""
    if os.name != "posix":  # no harmless test of another process's life there
        return
    pattern = re.compile(re.escape(f".{target.stem}.") + r"(\d+)-[0-9a-f]{12}" + re.escape(f".tmp{target.suffix}"))
    try:
        names = os.listdir(target.parent)
    except OSError:
        return
    for name in names:
        found = pattern.fullmatch(name)
        if found and not _alive(int(found.group(1))):
            with contextlib.suppress(OSError):
                os.unlink(target.parent / name)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


@contextlib.contextmanager
def locked(path: str | Path, what: str) -> Iterator[None]:
    """Own ``path`` for the block: an advisory lock (flock) on a hidden file beside it, ``.NAME.lock``, that holds
    the owner's pid; UsageError when another process owns it. The lock file, not the file itself, which its writer
    replaces whole (`atomic_path`) and whose readers (HDF5) take locks of their own. A killed owner's lock ends with
    it; its lock file is taken over and removed by the next owner."""
    try:
        import fcntl
    except ImportError:  # no flock (Windows): unlocked
        yield
        return
    target = Path(path)
    lock = target.with_name(f".{target.name}.lock")
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o666)
        except OSError as exc:  # a missing or read-only folder: the file itself could not be written either
            raise SceneError(f"cannot lock {what} {path}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            owner = os.read(fd, 32).decode(errors="replace").strip()
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise SceneError(f"cannot lock {what} {path}: {exc.strerror or exc}") from None
            raise UsageError(f"{what} {path} is in use by another run{f' (process {owner})' if owner else ''}: "
                             f"wait for it to end, or choose another file") from None
        # A former owner may have removed the lock file between our open and our lock: then ours is no lock.
        try:
            here = os.stat(lock)
        except FileNotFoundError:
            here = None
        mine = os.fstat(fd)
        if here is not None and (here.st_ino, here.st_dev) == (mine.st_ino, mine.st_dev):
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)


def package_version(name: str) -> str:
    from importlib import metadata  # here: the command line's start (finrft --help) needs no version

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "unknown"


def provenance() -> dict[str, str]:
    """The versions of finrft, MuJoCo and numpy, and the time of writing (UTC, ISO 8601)."""
    import mujoco  # here: `finrft --version` imports this module, and needs neither
    import numpy as np

    return {"finrft_version": package_version("finrft"), "mujoco_version": mujoco.__version__,
            "numpy_version": np.__version__,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
