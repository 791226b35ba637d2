"""The `mavtune` command (and `python -m mavtune`): signal handlers first, then the CLI, one line on any stop.

Nothing heavy is imported before the handlers are in place, so Ctrl-C at any moment — even inside an import —
ends in one line (`interrupted ...`, status 130) instead of a traceback. After an interrupt the process ends as
soon as the command has closed everything it opened: the exit handlers run, the interpreter's teardown (about
1 s of freeing numba's and matplotlib's modules) does not.
"""

from __future__ import annotations

import atexit
import os
import sys


class _QuietWhenClosed:
    """stdout that goes quiet, instead of failing the run, once its reader is gone (`mavtune tune | head -3`)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except (BrokenPipeError, ValueError):
            self._silence()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except (BrokenPipeError, ValueError):
            self._silence()

    def _silence(self) -> None:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, self._stream.fileno())
        except (OSError, ValueError):
            pass
        finally:
            os.close(devnull)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def main() -> None:
    """Entry point: install the interrupt handlers, guard stdout, run the CLI (mavtune.cli.run_app)."""
    from mavtune import interrupts

    interrupts.install()
    sys.stdout = _QuietWhenClosed(sys.stdout)
    try:
        from mavtune.cli import run_app
    except BaseException:  # Ctrl-C while the CLI itself is imported: nothing has started yet
        if not interrupts.received():
            raise
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    code = run_app()
    if code == 130:
        _exit_now(code)
    sys.exit(code)


def _exit_now(code: int) -> None:
    """Run the exit handlers, flush the output and end the process without the interpreter's teardown."""
    try:
        atexit._run_exitfuncs()  # logging's flush and every library's own; what we opened is closed already
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)


if __name__ == "__main__":
    main()
