"""A run folder's name checked before anything is read or written, and the folder held by one process at a time.

Kept apart from the report (which imports plotting) because `mavtune plan` and `--help` use it and import nothing
heavy."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mavtune.errors import MavtuneError

NAME_MAX = 255  # bytes in one file or folder name on Linux, macOS and Windows file systems


def usable_path(path: Path, what: str) -> Path:
    """`path` if the file system can hold its name: a part longer than the limit (255 bytes on most) is one line
    naming it, before anything is read, flown or written."""
    for part in path.parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            raise MavtuneError(f"{what} {str(path)[:60]}…: the name {part[:24]}… is {size} bytes, longer than the "
                               f"{NAME_MAX} a file system allows")
    return path



@contextmanager
def claimed(folder: Path) -> Iterator[None]:
    """Hold a run folder for this process (an advisory lock on the folder itself: no file is added, and the journal's
    own file is never opened here — closing a second descriptor of it would drop SQLite's locks on it): a second
    `mavtune tune` or `report` on the folder is refused in one line before it flies or writes anything there. The
    operating system drops the claim when the process ends, even by `kill -9`, so a crash never leaves it held."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise MavtuneError(f"run folder {folder} is in use by another mavtune process; wait for it to end, or "
                               "choose another --out") from None
        yield
    finally:
        os.close(fd)  # closing drops the lock
