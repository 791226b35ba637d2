"""Output folders of the commands (surface, reproduce, run reports): created and checked before any work starts."""

from __future__ import annotations

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from mavtune.errors import MavtuneError


def out_folder(path: str | Path) -> Path:
    """Create the output folder `path` (parents too) and check it can be written; a one-line error otherwise."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".mavtune-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except FileExistsError:
        raise MavtuneError(f"output folder {path} is a file") from None
    except OSError as exc:
        raise MavtuneError(f"cannot write to the output folder {path}: {exc.strerror or exc}") from None
    return path


def usable_path(path: Path, what: str) -> Path:
    """`path` if the file system can hold its name: a part longer than the limit (255 bytes on most) is one line
    naming it, before anything is read, flown or written."""
    for part in path.parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            raise MavtuneError(f"{what} {str(path)[:60]}…: the name {part[:24]}… is {size} bytes, longer than the "
                               f"{NAME_MAX} a file system allows")
    return path


NAME_MAX = 255  # bytes in one file or folder name on Linux, macOS and Windows file systems



@contextmanager
def claimed(journal: Path) -> Iterator[None]:
    """Hold a run folder for this process by its journal (an advisory lock: no file is added): a second `mavtune
    tune` or `report` on the folder is refused in one line before it flies or writes anything there. The
    operating system drops the claim when the process ends, even by `kill -9`, so a crash never leaves it held."""
    fd = os.open(journal, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise MavtuneError(f"run folder {journal.parent} is in use by another mavtune process; wait for it to "
                               "end, or choose another --out") from None
        yield
    finally:
        os.close(fd)  # closing drops the lock
