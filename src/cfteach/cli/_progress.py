"""Progress bars for steps that take more than a couple of seconds: on stderr, only on a
terminal, never under ``--quiet`` (so pipes, logs and tests stay clean)."""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

_quiet = False


def set_quiet(quiet: bool) -> None:
    """Called by every command with a ``--quiet`` option before its work."""
    global _quiet
    _quiet = bool(quiet)


def _stderr_is_terminal() -> bool:
    return sys.stderr.isatty()


def enabled() -> bool:
    """Show progress: not ``--quiet`` and stderr is a terminal."""
    return not _quiet and _stderr_is_terminal()


def bar(iterable: Iterable[Any] | None = None, *, total: int | None = None,
        desc: str = "") -> Any:  # noqa: ANN401 - a tqdm bar
    """A tqdm bar on stderr (disabled when `enabled()` is false)."""
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, file=sys.stderr, disable=not enabled(),
                leave=False, dynamic_ncols=True)


@contextmanager
def busy(desc: str) -> Iterator[None]:
    """A step whose progress cannot be counted: elapsed seconds, ticking on stderr."""
    if not enabled():
        yield
        return
    done = threading.Event()
    with bar(desc=desc) as b:
        def tick() -> None:
            while not done.wait(0.5):
                b.refresh()

        thread = threading.Thread(target=tick, daemon=True)
        thread.start()
        start = time.monotonic()
        try:
            yield
        finally:
            done.set()
            thread.join()
            b.set_postfix_str(f"{time.monotonic() - start:.0f} s")
