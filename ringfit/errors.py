"""The one exception type for bad input at ringfit's edges.

Its message is a single line that names the file, row or field and says what
was expected; the CLI prints it and exits with status 2.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: unreadable file, missing column, non-finite or out-of-range value.

    One line naming the file (``source``), row, field or option and what was expected;
    the command line prints it and exits with status 2.

    Examples
    --------
    >>> from ringfit.errors import InputError
    >>> from ringfit.io.tyre import read_tyre
    >>> try:
    ...     read_tyre("no-such.tyre.toml")
    ... except InputError as exc:
    ...     print(exc)
    no-such.tyre.toml: file not found
    >>> print(InputError("expected a number of bar,   got 'high'", source="tyre.toml"))  # always one line
    tyre.toml: expected a number of bar, got 'high'
    """

    def __init__(self, message: str, *, source: object | None = None):
        text = " ".join(str(message).split())  # always one line
        if source is not None:
            text = f"{source}: {text}"
        super().__init__(text)
