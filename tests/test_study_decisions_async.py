"""The event loop's wait for a closed-loop decision (`result_or_none_async`).

A page polls `GET /api/state` with ``wait=0``. A decision that finished after its event's
short wait must be taken by such a poll: before, `asyncio.wait_for` of the wrapped future
with a timeout of 0 always timed out, and a participant whose first decision took longer
than the event's wait (a loaded server) saw "Preparing the next item" for ever."""

from __future__ import annotations

import asyncio
import threading
from concurrent.futures import Future

from cfteach.study.decisions import result_or_none, result_or_none_async


def _run(fut: Future, timeout: float) -> tuple[bool, object]:
    return asyncio.run(result_or_none_async(fut, timeout))


def test_a_finished_decision_is_taken_with_no_wait() -> None:
    fut: Future = Future()
    fut.set_result({"index": 0})
    assert _run(fut, 0.0) == (True, {"index": 0}) == result_or_none(fut, 0.0)


def test_none_is_a_result_and_a_failure_is_not() -> None:
    over: Future = Future()
    over.set_result(None)  # teaching is over: a finished decision
    assert _run(over, 0.0) == (True, None)
    failed: Future = Future()
    failed.set_exception(RuntimeError("worker died"))
    assert _run(failed, 0.0) == (False, None) == result_or_none(failed, 0.0)


def test_an_unfinished_decision_is_waited_for_up_to_the_timeout() -> None:
    fut: Future = Future()
    assert _run(fut, 0.0) == (False, None)
    assert _run(fut, 0.05) == (False, None)
    threading.Timer(0.05, fut.set_result, args=({"index": 3},)).start()
    assert _run(fut, 5.0) == (True, {"index": 3})
    assert not fut.cancelled()  # the wait never cancels the decision itself
