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
