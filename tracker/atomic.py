"""Files that are either complete or absent: write to a temporary file beside the target, then
rename it over the target (atomic on POSIX). A failure leaves the old file as it was."""

from __future__ import annotations

import contextlib
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yields a temporary path in ``path``'s folder (same suffix, so format-by-extension writers
    work); on a clean exit it is flushed to disk and renamed over ``path``, otherwise removed.
    Raises OSError (e.g. a missing folder) like ``open`` would."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        # Only now: while written it stays mkstemp's 0600 (its writer must be able to open it, whatever
        # the mode of the file it replaces, a read-only one included).
        os.chmod(tmp, replacing_mode(target))
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def replacing_mode(target: str | os.PathLike) -> int:
    """The permissions a file written over ``target`` should have: those of the file it replaces,
    or a new file's (0666 less the umask). mkstemp makes its files private (0600), and a calibration
    or pose file renamed into place so stayed unreadable to the cell's other users."""
    try:
        return stat.S_IMODE(os.stat(target).st_mode)
    except OSError:
        return 0o666 & ~_umask()


def _umask() -> int:
    # Read without setting it where Linux tells it (os.umask sets it, for a moment, for every thread).
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask
