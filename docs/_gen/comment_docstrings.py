"""griffe extension: a module or class attribute's ``#:`` comment is its docstring.

ringfit documents its constants the Sphinx way, with ``#:`` comment lines right above the
assignment (``#: Stop when the chain is longer than this many integrated autocorrelation
times.``); griffe reads only string literals after an assignment. This gives the comment to
an attribute that has no docstring of its own, so the API reference shows it.
"""

from __future__ import annotations

import griffe


class CommentDocstrings(griffe.Extension):
    """Attach ``#:`` comment blocks above an assignment as the attribute's docstring."""

    def on_attribute_instance(self, *, node, attr, agent, **kwargs) -> None:  # noqa: D102
        if attr.docstring is not None or attr.lineno is None:
            return
        try:
            lines = attr.parent.lines if attr.parent is not None else []
        except Exception:  # no source (a compiled module)
            return
        i = attr.lineno - 2  # the line above the assignment, 0-based
        block = []
        while 0 <= i < len(lines) and lines[i].lstrip().startswith("#:"):
            block.append(lines[i].lstrip()[2:].strip())
            i -= 1
        if block:
            attr.docstring = griffe.Docstring("\n".join(reversed(block)), lineno=i + 2, parent=attr)
