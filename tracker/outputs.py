"""Output files that never destroy an input, each other, or an existing file for nothing.

Two rules, checked before anything is opened or written:

* an output may not be the same file as an input or another output (by path, and by inode, so
  hard and symbolic links are caught), nor a frame of an image-sequence source;
* an output is written under a temporary name beside its target and moved into place only once
  there is something to keep (the first frame processed), so bad input found at start, or an
  error at frame 0, leaves an existing file exactly as it was.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from tracker.atomic import replacing_mode
from tracker.errors import BadInput


def _identity(path: str) -> tuple[str, tuple[int, int] | None]:
    """The resolved path, and (device, inode) when the file exists."""
    resolved = os.path.realpath(path)
    try:
        st = os.stat(resolved)
    except OSError:
        return resolved, None
    return resolved, (st.st_dev, st.st_ino)


def _same(a: str, b: str) -> bool:
    path_a, inode_a = _identity(a)
    path_b, inode_b = _identity(b)
    return path_a == path_b or (inode_a is not None and inode_a == inode_b)


def _sequence_regex(pattern: str) -> re.Pattern[str]:
    """A printf image pattern (``frames/%05d.png``) as a regex over resolved paths."""
    resolved = os.path.join(os.path.realpath(os.path.dirname(pattern) or "."), os.path.basename(pattern))
    parts = re.split(r"%0?\d*d", resolved)
    return re.compile(r"\d+".join(re.escape(p) for p in parts) + r"\Z")


def refuse_clashes(outputs: dict[str, str | None], inputs: dict[str, str | None]) -> None:
    """Raise BadInput (exit 2) when an output would overwrite an input or another output.

    Keys are option names (``--record``), values paths (None: not given). An input whose
    name contains ``%`` is an image-sequence pattern: every file it names is an input."""
    given_out = [(opt, p) for opt, p in outputs.items() if p]
    for i, (opt, path) in enumerate(given_out):
        for other_opt, other in given_out[i + 1:]:
            if _same(path, other):
                raise BadInput(f"{opt} {path}: is the same file as {other_opt} {other}; give them different names")
        for in_opt, in_path in inputs.items():
            if not in_path:
                continue
            if "%" in in_path:
                if _sequence_regex(in_path).match(os.path.realpath(path)):
                    raise BadInput(f"{opt} {path}: is a frame of {in_opt} {in_path}; it would be overwritten")
            elif _same(path, in_path):
                raise BadInput(f"{opt} {path}: is the same file as {in_opt} {in_path}; it would be overwritten")


def check_target(option: str, target: str, what: str) -> str:
    """The folder ``target`` goes in; BadInput (exit 2) when it cannot be a file there (``option``: the
    option that named it, "" for none)."""
    where = f"{option} {target}" if option else target
    if os.path.isdir(target):
        raise BadInput(f"{where}: cannot write {what}: it is a folder; expected a file name")
    check_writable(Path(target), what, where)
    return os.path.dirname(os.path.abspath(target))


def check_writable(path: Path, what: str, where: str | None = None) -> None:
    """BadInput (exit 2) unless ``what`` can be written at ``path`` (``where``: how the message names
    it): its folder exists and may be written in (checked before any work, so that none is lost to an
    output that cannot be kept)."""
    parent = path.parent if str(path.parent) else Path(".")
    where = where or str(path)
    if not parent.is_dir():
        raise BadInput(f"{where}: cannot write {what}: the folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BadInput(f"{where}: cannot write {what}: the folder {parent} is not writable")


class StagedFile:
    """A temporary file beside ``target``; ``publish()`` moves it into place, ``discard()`` removes it.

    Writers open ``path`` (the temporary name, same suffix, so format-by-extension writers work).
    An open descriptor keeps writing to the same file after the rename, so a writer may publish
    as soon as it has something worth keeping and go on writing."""

    def __init__(self, option: str, target: str, what: str = "the file") -> None:
        self.option = option
        self.target = target
        folder = check_target(option, target, what)
        name = Path(target)
        try:
            fd, self.path = tempfile.mkstemp(prefix=f".{name.stem}.", suffix=f".partial{name.suffix}", dir=folder)
        except OSError as exc:
            raise BadInput(f"{option} {target}: cannot write {what}: {exc.strerror}") from None
        os.close(fd)
        self.published = False

    def publish(self) -> None:
        if not self.published:
            os.chmod(self.path, replacing_mode(self.target))  # its writer has it open already
            os.replace(self.path, self.target)
            self.published = True

    def discard(self) -> None:
        if not self.published and os.path.exists(self.path):
            os.unlink(self.path)


class PublishOnFirstFrame:
    """Wraps a sink writing into a ``StagedFile``: the file takes its real name once the first
    frame has been handed to the sink, and is removed if the run ends before any frame."""

    def __init__(self, sink, staged: StagedFile) -> None:
        self.sink = sink
        self.staged = staged

    def submit(self, frame, result) -> None:
        self.sink.submit(frame, result)
        if not self.staged.published:
            self.staged.publish()

    def status(self) -> str:
        return self.sink.status()

    def close(self) -> None:
        try:
            self.sink.close()
        finally:
            self.staged.discard()

    def __getattr__(self, name: str):
        # Everything else (counters, live state) is the wrapped sink's.
        return getattr(self.sink, name)
