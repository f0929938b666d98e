"""In-memory sliding-window rate limits (client addresses are used here and never stored)."""

from __future__ import annotations

import threading
import time
from collections import deque


class RateLimiter:
    """At most `limit` hits per `window` seconds per key; `limit <= 0` disables it.

    Memory is bounded: keys are short (callers pass addresses or well-formed tokens only),
    and beyond `max_keys` idle keys are forgotten, then the oldest ones.
    """

    def __init__(self, limit: int, window: float = 60.0, max_keys: int = 20_000) -> None:
        self.limit, self.window, self.max_keys = limit, window, max_keys
        self._hits: dict[str, deque[float]] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._hits)

    def allow(self, key: str, now: float | None = None) -> bool:
        """Count a hit for `key` unless it is over the limit; False if it is."""
        if self.limit <= 0:
            return True
        now = time.monotonic() if now is None else now
        with self._lock:
            q = self._recent(key, now, create=True)
            if len(q) >= self.limit:
                return False
            q.append(now)
            return True

    def blocked(self, key: str, now: float | None = None) -> bool:
        """Whether `key` is at its limit now (counts nothing)."""
        if self.limit <= 0:
            return False
        now = time.monotonic() if now is None else now
        with self._lock:
            q = self._recent(key, now, create=False)
            return q is not None and len(q) >= self.limit

    def hit(self, key: str, now: float | None = None) -> None:
        """Count one hit for `key` (a failure to remember), whether or not it is over."""
        if self.limit <= 0:
            return
        now = time.monotonic() if now is None else now
        with self._lock:
            q = self._recent(key, now, create=True)
            q.append(now)
            while len(q) > self.limit:  # more than `limit` hits tell nothing more
                q.popleft()

    def _recent(self, key: str, now: float, *, create: bool) -> deque[float] | None:
        q = self._hits.get(key)
        if q is None:
            if not create:
                return None
            if len(self._hits) >= self.max_keys:
                self._forget(now)
            q = self._hits[key] = deque()
        while q and q[0] <= now - self.window:
            q.popleft()
        return q

    def _forget(self, now: float) -> None:
        self._hits = {k: q for k, q in self._hits.items() if q and q[-1] > now - self.window}
        if len(self._hits) >= self.max_keys:  # still full of active keys: drop the oldest half
            for k in list(self._hits)[: len(self._hits) - self.max_keys // 2]:
                del self._hits[k]
