"""Output folders of the commands (surface, reproduce, run reports): created and checked before any work starts."""

from __future__ import annotations

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

