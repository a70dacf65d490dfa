"""The one writer of every file crosscert produces (CSV, JSON, PNG).

Rules, in the order they are checked:

* the target is a new path or an existing **regular** file; a device, a
  directory, a pipe or a socket is refused (``/dev/null`` stays a device);
* a symbolic link is **followed**: its target is replaced and the link kept,
  so a link into a shared results folder keeps pointing where it did;
* the content goes to a temporary file in the target's folder, is flushed to
  disk and renamed over the target in one step, so a reader sees the old file
  or the new one, never a part;
* an existing file keeps its permission bits; a new file gets ``0666`` less
  the process umask, like any file a shell redirection creates;
* on any failure, Ctrl-C or SIGTERM the temporary file is removed and the
  target is left as it was.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import stat
import tempfile
import threading
from pathlib import Path
from typing import Callable, IO

from crosscert.robots.errors import InputError

__all__ = ["check_output_path", "atomic_write"]

log = logging.getLogger(__name__)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output_path(path, *, what: str = "output") -> Path:
    """The real path a write to ``path`` would replace, or InputError saying why not.

    Call it before any heavy work, so a bad path is refused first.

    Parameters
    ----------
    path : str or Path
        Where the user asked us to write.
    what : str
        The option's name, for messages (``"--out"``).
    """
    if str(path) == "":
        raise InputError(f"{what}: empty path")
    p = Path(path)
    real = Path(os.path.realpath(p))  # follow a symlink (the documented rule)
    if real.exists() or real.is_symlink():
        try:
            mode = real.stat().st_mode
        except OSError as exc:
            raise InputError(f"{what}: cannot use {p}: {exc.strerror}") from None
        if not stat.S_ISREG(mode):
            kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file"
            raise InputError(f"{what}: {p} is {kind}; give a new path or a regular file to replace")
        if not os.access(real, os.W_OK):
            raise InputError(f"{what}: {p} is not writable")
    folder = real.parent
    if not folder.is_dir():
        raise InputError(f"{what}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what}: folder {folder} is not writable")
    return real


@contextlib.contextmanager
def _sigterm_as_exit():
    """Within the block, SIGTERM unwinds like Ctrl-C (so ``finally`` clauses run)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _raise(signum, frame):
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, _raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def atomic_write(path, fill: Callable[[IO], None], *, binary: bool = False, what: str = "output") -> Path:
    """Write a file by calling ``fill(handle)`` and renaming the result over ``path``.

    Parameters
    ----------
    path : str or Path
        Target (see the module's rules).
    fill : callable
        Writes the whole content to the open handle it is given (text with
        ``newline=""`` or binary).
    binary : bool
        Open the temporary file in binary mode.
    what : str
        The option's name, for messages.

    Returns
    -------
    Path
        The file written (a symlink's target when ``path`` is a link).
    """
    real = check_output_path(path, what=what)
    mode = stat.S_IMODE(real.stat().st_mode) if real.exists() else 0o666 & ~_umask()
    with _sigterm_as_exit():
        fd, tmp = tempfile.mkstemp(prefix=f".{real.name}.", suffix=".tmp", dir=real.parent)
        try:
            with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"newline": ""})) as fh:
                fill(fh)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, real)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    log.debug("wrote %s", real)
    return real
