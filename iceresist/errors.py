"""User-facing errors: one line that names the field and the fix; the CLI exits with status 2."""


class InputError(ValueError):
    """Bad input (scene file, CLI flag, ship data). The message is shown as-is, without a traceback."""


class StabilityError(InputError):
    """A setting that cannot run stably (tau <= 1/2, Mach too high, DEM step above critical)."""
