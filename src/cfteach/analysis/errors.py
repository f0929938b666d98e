"""The error of an export that cannot be analysed, shared by the reader and its checks.

It lives apart so that `io` (which reads an export) and `validate` (which checks it) both
stand on it without importing each other.
"""

from __future__ import annotations


class ExportError(ValueError):
    """A study export that cannot be analysed: the message names the file and column."""
