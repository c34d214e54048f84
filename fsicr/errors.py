"""User-facing errors of the FSICR calculator.

The package imports nothing from the engine, so it carries its own error type;
the command line turns it into one line on stderr and exit status 2.
"""


class FsicrInputError(ValueError):
    """Bad ship data or option. The message names the field and what is allowed."""


def short_text(text: str, most: int = 60) -> str:
    """``text`` quoted for a one-line message: whole up to ``most`` characters, else its start and its length."""
    if len(text) <= most:
        return repr(text)
    return f"{text[:most - 20]!r}... ({len(text)} characters)"


def unusable_name(text: str, exc: Exception, what: str) -> str:
    """Why the file system refused ``text`` as the name of a ``what`` (too long, a NUL byte), for a one-line
    message: ``'aaa...'... (5004 characters) cannot be a file name here (File name too long)``."""
    return f"{short_text(text)} cannot be a {what} name here ({getattr(exc, 'strerror', None) or exc})"


def too_long_path(exc: OSError) -> str | None:
    """The one line a command prints for a path the file system found too long (ENAMETOOLONG) where no check
    before caught it; None for any other error, which stays an error of the tool."""
    import errno

    if exc.errno != errno.ENAMETOOLONG:
        return None
    return f"a path is too long for the file system: {short_text(str(exc.filename))}; give a shorter one"
