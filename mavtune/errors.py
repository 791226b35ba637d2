"""The one error type users see: a one-line message naming what is wrong, never a traceback."""


class MavtuneError(Exception):
    """Bad input or a failed precondition; the CLI prints `error: <message>` and exits with status 2."""
