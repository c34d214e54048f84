"""User-facing errors of the FSICR calculator.

The package imports nothing from the engine, so it carries its own error type;
the command line turns it into one line on stderr and exit status 2.
"""


class FsicrInputError(ValueError):
    """Bad ship data or option. The message names the field and what is allowed."""
