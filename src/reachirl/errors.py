"""Errors that the command line turns into exit code 2 and a one-line message."""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad input: a file, a line or frame, and what was expected.

    ``str(err)`` is the whole one-line message, e.g. ``"trials.npz: q has shape (3,), expected (n, 2)"``.
    """

    def __init__(self, message: str, path: object | None = None, where: str | None = None):
        parts = [str(path)] if path is not None else []
        if where:
            parts.append(str(where))
        self.path, self.where, self.reason = path, where, message
        text = ": ".join([*parts, message]) if parts else message
        # one line, whatever the input held (a field quoted from a garbled file may hold line breaks)
        super().__init__(text.replace("\r", "\\r").replace("\n", "\\n"))
