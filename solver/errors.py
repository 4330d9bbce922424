"""Error types. Every error a user can cause derives from `InputError` and says what to fix."""


class DynsplinesError(Exception):
    """Base class of every error this project raises on purpose."""


class InputError(DynsplinesError, ValueError):
    """Bad user input: a file, a field, a value. The message names them and gives the fix."""
