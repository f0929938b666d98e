"""Each decision worker takes the decisions a page waits for before the ones made ahead,
so a wave of participants answering tests together is not queued behind items nobody has
reached yet (bench/bench_closed_loop_study.py, docs/study.md "Load")."""

from __future__ import annotations

import threading
import time

from cfteach.study.decisions import Decider

STUDY = {"version": "v1"}


class _Live:
    """Stands in for LiveTeaching: records the order of its decisions; the first one waits
    for `gate`, so everything after it is queued while it runs."""

    def __init__(self, kind: str = "test") -> None:
        self.gate, self.order, self.kind = threading.Event(), [], kind
        self._lock = threading.Lock()

    def decide(self, study, pk, seed, domain, responses, served=None):
        if not self.order:
            self.gate.wait(30)
        with self._lock:
            self.order.append((pk, len(responses)))
        return None, None  # teaching over: no ahead decision follows


def _wait(futs) -> None:
    for f in futs:
        f.result(timeout=30)


def test_a_waited_for_decision_goes_before_queued_ahead_decisions() -> None:
    live = _Live()
    d = Decider(live, [], 0)  # one in-process worker, so one queue
    try:
        first = d.submit(STUDY, 0, 0, "skateboard", [])
        while not live.order and not first.running():
            time.sleep(0.01)
        ahead = [d.submit(STUDY, pk, 0, "skateboard", [{}], urgent=False) for pk in (1, 2, 3)]
        waited = d.submit(STUDY, 4, 0, "skateboard", [{}])
        live.gate.set()
        _wait([first, *ahead, waited])
        assert live.order == [(0, 0), (4, 1), (1, 1), (2, 1), (3, 1)]
    finally:
        d.close()


def test_an_ahead_decision_a_page_then_asks_for_is_taken_first() -> None:
    live = _Live()
    d = Decider(live, [], 0)
    try:
        first = d.submit(STUDY, 0, 0, "skateboard", [])
        while not live.order and not first.running():
            time.sleep(0.01)
        ahead = [d.submit(STUDY, pk, 0, "skateboard", [{}], urgent=False) for pk in (1, 2, 3)]
        again = d.submit(STUDY, 3, 0, "skateboard", [{}])  # the page reached item 3's
        assert again is ahead[2]  # the same decision, not a second one
        live.gate.set()
        _wait([first, *ahead])
        assert live.order == [(0, 0), (3, 1), (1, 1), (2, 1)]
    finally:
        d.close()


def test_closing_cancels_queued_decisions() -> None:
    live = _Live()
    d = Decider(live, [], 0)
    first = d.submit(STUDY, 0, 0, "skateboard", [])
    while not live.order and not first.running():
        time.sleep(0.01)
    queued = d.submit(STUDY, 1, 0, "skateboard", [])
    d.close()
    live.gate.set()
    assert queued.cancelled()


def test_a_killed_worker_is_replaced_and_its_decisions_made_again() -> None:
    """A worker killed outright (out of memory) fails at most the decision it held; the
    lane starts a new worker, and asking again gets the decision."""
    import os
    import signal
    from concurrent.futures.process import BrokenProcessPool

    from cfteach.study.live import LiveTeaching

    d = Decider(LiveTeaching(), [], 1)
    try:
        lane = d._lanes[0]
        pid = next(iter(d._executors[0]._processes))
        os.kill(pid, signal.SIGKILL)
        answers, failures = [], 0
        while len(answers) < 2 and failures < 3:
            try:
                answers.append(lane.put(os.getpid, (), urgent=True).result(timeout=120))
            except BrokenProcessPool:
                failures += 1
        assert failures <= 1
        assert len(answers) == 2 and pid not in answers and os.getpid() not in answers
    finally:
        d.close()
