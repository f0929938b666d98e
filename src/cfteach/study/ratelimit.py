"""In-memory sliding-window rate limits (client addresses are used here and never stored)."""

from __future__ import annotations

import threading
import time
from collections import deque


class RateLimiter:
    """At most `limit` hits per `window` seconds per key; `limit <= 0` disables it. A hit
    may weigh more or less than one (`allow(key, cost)`): limits are on the work a client
    asks for, not on its number of requests.

    Memory is bounded: keys are short (callers pass addresses or well-formed tokens only),
    and beyond `max_keys` idle keys are forgotten, then the oldest ones.
    """

    def __init__(self, limit: int, window: float = 60.0, max_keys: int = 20_000) -> None:
        self.limit, self.window, self.max_keys = limit, window, max_keys
        self._hits: dict[str, deque[tuple[float, float]]] = {}
        self._sums: dict[str, float] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._hits)

    def allow(self, key: str, now: float | None = None, cost: float = 1.0) -> bool:
        """Count a hit of weight `cost` for `key` unless that would pass the limit; False
        if it would (nothing is counted then)."""
        if self.limit <= 0:
            return True
        now = time.monotonic() if now is None else now
        with self._lock:
            q = self._recent(key, now)
            if self._sums.get(key, 0.0) + cost > self.limit + 1e-9:
                return False
            q.append((now, cost))
            self._sums[key] = self._sums.get(key, 0.0) + cost
            return True

    def blocked(self, key: str, now: float | None = None) -> bool:
        """Whether `key` is at its limit now (counts nothing)."""
        if self.limit <= 0:
            return False
        now = time.monotonic() if now is None else now
        with self._lock:
            if key not in self._hits:
                return False
            self._recent(key, now)
            return self._sums.get(key, 0.0) >= self.limit - 1e-9

    def hit(self, key: str, now: float | None = None) -> None:
        """Count one hit for `key` (a failure to remember), whether or not it is over."""
        if self.limit <= 0:
            return
        now = time.monotonic() if now is None else now
        with self._lock:
            q = self._recent(key, now)
            q.append((now, 1.0))
            self._sums[key] = self._sums.get(key, 0.0) + 1.0
            while len(q) > self.limit:  # more than `limit` hits tell nothing more
                self._sums[key] -= q.popleft()[1]

    def _recent(self, key: str, now: float) -> deque[tuple[float, float]]:
        """`key`'s hits within the window (a new, empty window if it has none)."""
        q = self._hits.get(key)
        if q is None:
            if len(self._hits) >= self.max_keys:
                self._forget(now)
            q = self._hits[key] = deque()
        while q and q[0][0] <= now - self.window:
            self._sums[key] -= q.popleft()[1]
        if not q:
            self._sums[key] = 0.0  # no float drift left behind
        return q

    def _forget(self, now: float) -> None:
        self._hits = {k: q for k, q in self._hits.items() if q and q[-1][0] > now - self.window}
        if len(self._hits) >= self.max_keys:  # still full of active keys: drop the oldest half
            for k in list(self._hits)[: len(self._hits) - self.max_keys // 2]:
                del self._hits[k]
        self._sums = {k: self._sums.get(k, 0.0) for k in self._hits}
