"""Files that are either complete or absent: write to a temporary file beside the target, then
rename it over the target (atomic on POSIX). A failure leaves the old file as it was."""

from __future__ import annotations

import contextlib
import os
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
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
