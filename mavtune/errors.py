"""The one error type users see: a one-line message naming what is wrong, never a traceback."""


class MavtuneError(Exception):
    """Bad input or a failed precondition; the CLI prints `error: <message>` and exits with status 2."""


class Interrupted(MavtuneError):
    """Ctrl-C (or SIGTERM) during a run: every finished round is in the journal; the message says how to resume.
    The CLI prints it as one line and exits with status 130."""
