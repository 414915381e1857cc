"""The one exception type for bad input at ringfit's edges.

Its message is a single line that names the file, row or field and says what
was expected; the CLI prints it and exits with status 2.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: unreadable file, missing column, non-finite or out-of-range value."""

    def __init__(self, message: str, *, source: object | None = None):
        text = " ".join(str(message).split())  # always one line
        if source is not None:
            text = f"{source}: {text}"
        super().__init__(text)
