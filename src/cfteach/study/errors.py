"""The one exception a refused request raises anywhere in the study service."""

from __future__ import annotations


class ApiError(Exception):
    """A request the server refuses; `status` is the HTTP code, `code` a stable name."""

    def __init__(self, status: int, code: str, message: str) -> None:
        super().__init__(message)
        self.status, self.code, self.message = status, code, message
