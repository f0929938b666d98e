"""Closed-loop decisions off the request path: worker processes (or one thread) decide the
next item from a participant's stored responses; requests only submit and read results.

A decision is a pure function of (study file, session seed, domain, responses), so any
worker, any server process, and any retry gets the same item: nothing here is the only
copy of anything. Sessions are routed to a fixed worker (`pk % workers`), so each worker
keeps the teachers of its own sessions warm (`cfteach.study.live.LiveTeaching`), and after
an item whose response is known in advance (a demonstration or feedback: ``{}``) the item
after it is decided ahead, in the same worker. A failed answer's decision is its feedback,
chosen before the answer's belief update (`ClosedLoopTeacher._settle`): the update runs in
the decision made ahead, while the participant studies the feedback. Each worker takes the
decisions a page is waiting for before the ones made ahead (`DecisionLane`): when many
participants answer a test at once, their next items are not queued behind items nobody
has reached yet.

Why processes: a decision is numpy and Python on one core, a few ms at the median and up to
0.1-0.3 s after a long answer (bench/bench_closed_loop.py). In threads of the web server it
holds the interpreter, and every other request waits behind it (the third-pass review
measured page p99 of 0.5-1.8 s with 100 closed-loop participants).
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from threadpoolctl import threadpool_limits

from .live import LiveTeaching, ReplayMismatch
from .livesrv import settle_heap

#: Futures kept for lookup (the in-flight and recently finished decisions).
MAX_FUTURES = 4096
#: Seconds a worker may take to start and build its lesson pools.
WARM_TIMEOUT_S = 600.0
#: Seconds between a worker's checks that its server is still there.
PARENT_CHECK_S = 1.0
#: BLAS threads per decision worker. OpenBLAS starts one thread per core in every process,
#: and its idle threads spin while they wait for work: two workers and a web server on two
#: cores, each with such threads, spent ~50 ms of CPU per decision that takes ~4 ms on one
#: thread (measured with 20 skateboard sessions through `Decider`, docs/study.md "Load").
#: A decision's matrices (particles x features) are far too small to gain from threads.
WORKER_BLAS_THREADS = 1
#: How much lower than its server a decision worker runs (os.nice). On a saturated machine
#: the server's event and page requests (a few ms each) then win the CPU, and decisions
#: (tens of ms each, which the page already waits for behind "preparing") take what is left.
DECISION_NICE = 10

_WORKER_LIVE: LiveTeaching | None = None


def slim_study(study: dict, domain: str | None = None) -> dict:
    """What a worker needs of a study: its version and closed-loop cells (small to send)."""
    cells = study.get("closed_loop", {})
    if domain is not None:
        cells = {domain: cells[domain]}
    return {"version": study["version"], "closed_loop": cells}


def _exit_with(parent: int) -> None:
    """End this worker once its server is gone. A server killed outright (SIGKILL, out of
    memory) cannot shut its pool down, and an idle worker waiting for work never notices:
    it would stay forever, holding its lesson pools' memory."""
    while os.getppid() == parent:
        time.sleep(PARENT_CHECK_S)
    os._exit(0)


def _worker_init(studies: list[dict]) -> None:
    """In each worker process: one `LiveTeaching` with every pool built now (at start)."""
    global _WORKER_LIVE
    threading.Thread(target=_exit_with, args=(os.getppid(),), daemon=True).start()
    os.nice(DECISION_NICE)
    threadpool_limits(limits=WORKER_BLAS_THREADS)  # for the life of the process
    _WORKER_LIVE = LiveTeaching()
    for s in studies:
        _WORKER_LIVE.warm(s)
    settle_heap()  # a full collection would otherwise walk the pools during decisions


def _ready() -> bool:
    return _WORKER_LIVE is not None


def decide_job(study: dict, session_pk: int, seed: int, domain: str,
               responses: list[dict], served: list[list] | None = None) -> dict | None:
    """The item after `responses` as plain data (None: teaching is over). Runs in a worker."""
    live = _WORKER_LIVE
    if live is None:  # first use in this process (the in-process thread mode)
        raise RuntimeError("decision worker not initialised")
    return _decide(live, study, session_pk, seed, domain, responses, served)


def _decide(live: LiveTeaching, study: dict, session_pk: int, seed: int, domain: str,
            responses: list[dict], served: list[list] | None = None) -> dict | None:
    """The item after `responses`; ``{"mismatch": why}`` when the teacher rebuilt from them
    would have served other items than `served` (a result, not a failure: retrying would
    replay the same answers to the same end)."""
    try:
        item, summary = live.decide(study, session_pk, seed, domain, responses, served)
    except ReplayMismatch as e:
        return {"mismatch": str(e), "responses": len(responses)}
    if item is None:
        return None
    return {"index": int(item.index), "kind": item.kind, "purpose": item.purpose,
            "demo": int(item.demo), "about": None if item.about is None else int(item.about),
            "responses": len(responses), **(summary or {})}


class DecisionLane:
    """One worker's queue: decisions a page waits for (urgent) before decisions made ahead,
    first come first served within each; one decision in the worker at a time, so the
    order is ours, not the executor's FIFO.

    Why: participants at the same point of a study answer their tests together. Measured
    with 100 closed-loop participants in lockstep (`bench/bench_closed_loop_study.py`),
    every answered test's decision was followed at once by an ahead decision for the
    item after it, in the same FIFO, so the last answers of a wave waited behind the
    first ones' ahead work as well as their own."""

    def __init__(self, make_executor: Callable[[], Executor]) -> None:
        self._make = make_executor
        self.executor = make_executor()
        self._heap: list[tuple[int, int, Future]] = []
        self._jobs: dict[Future, tuple[Callable, tuple]] = {}
        self._urgent: set[Future] = set()
        self._seq = itertools.count()
        self._cv = threading.Condition()
        self._swap = threading.Lock()  # the lane thread and `heal` may both replace
        self._closed = False
        self._thread = threading.Thread(target=self._loop, daemon=True, name="cl-lane")
        self._thread.start()

    def put(self, fn: Callable, args: tuple, *, urgent: bool) -> Future:
        fut: Future = Future()
        with self._cv:
            if self._closed:
                raise RuntimeError("decision lane closed")
            self._jobs[fut] = (fn, args)
            self._push(fut, urgent)
            self._cv.notify()
        return fut

    def promote(self, fut: Future) -> None:
        """A page now waits for `fut`, queued as an ahead decision: take it before them."""
        with self._cv:
            if fut in self._jobs and fut not in self._urgent:
                self._push(fut, True)  # the old heap entry is skipped when popped

    def _push(self, fut: Future, urgent: bool) -> None:
        if urgent:
            self._urgent.add(fut)
        heapq.heappush(self._heap, (0 if urgent else 1, next(self._seq), fut))

    def _take(self) -> tuple[Future, Callable, tuple] | None:
        with self._cv:
            while True:
                while not self._heap and not self._closed:
                    self._cv.wait()
                if self._closed:
                    return None
                _, _, fut = heapq.heappop(self._heap)
                job = self._jobs.pop(fut, None)
                if job is not None:  # None: taken already through a promoted entry
                    self._urgent.discard(fut)
                    return fut, *job

    def _loop(self) -> None:
        while (taken := self._take()) is not None:
            fut, fn, args = taken
            if not fut.set_running_or_notify_cancel():
                continue
            ex = self.executor
            try:
                ex, inner = self._submit(fn, args)
                out = inner.result()
            except BaseException as e:  # noqa: BLE001 - handed to whoever waits for it
                if isinstance(e, BrokenProcessPool):
                    self._replace(ex)
                fut.set_exception(e)
            else:
                fut.set_result(out)

    def _submit(self, fn: Callable, args: tuple) -> tuple[Executor, Future]:
        """Into the worker; a worker that died (killed, out of memory) is replaced once, as
        its decisions can simply be made again."""
        ex = self.executor
        try:
            return ex, ex.submit(fn, *args)
        except (BrokenProcessPool, RuntimeError):
            self._replace(ex)
            ex = self.executor
            return ex, ex.submit(fn, *args)

    def _replace(self, broken: Executor | None = None) -> None:
        with self._swap:
            if broken is not None and self.executor is not broken:
                return  # replaced already
            self.executor.shutdown(wait=False, cancel_futures=True)
            self.executor = self._make()

    def heal(self) -> None:
        ex = self.executor
        if getattr(ex, "_broken", False):
            self._replace(ex)

    def close(self) -> None:
        with self._cv:
            self._closed = True
            for fut in self._jobs:
                fut.cancel()
            self._jobs.clear()
            self._cv.notify_all()
        self.executor.shutdown(wait=False, cancel_futures=True)


class Decider:
    """Submits decisions to `workers` single-process pools (0: one thread of this process,
    sharing `live`; for tests and tiny studies), each fed by its `DecisionLane`, and
    remembers their futures."""

    def __init__(self, live: LiveTeaching, studies: list[dict], workers: int) -> None:
        self.live, self.workers = live, workers
        self._studies = [slim_study(s) for s in studies if s.get("closed_loop")]
        self._lock = threading.Lock()
        self._futures: dict[tuple, Future] = {}
        self._lanes = [DecisionLane(self._executor) for _ in range(max(1, workers))]
        # follow-up submissions leave the thread that finished a future (for a process
        # pool, its manager thread) at once
        self._dispatch = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cl-dispatch")
        if workers > 0:  # start the workers and build their pools now, not on first use
            for f in [ex.submit(_ready) for ex in self._executors]:
                f.result(timeout=WARM_TIMEOUT_S)

    @property
    def _executors(self) -> list[Executor]:
        return [lane.executor for lane in self._lanes]

    def _executor(self) -> Executor:
        if self.workers <= 0:
            return ThreadPoolExecutor(max_workers=1, thread_name_prefix="closed-loop")
        # spawn, not fork: the server has threads (uvicorn, the database pool)
        return ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init, initargs=(self._studies,))

    def close(self) -> None:
        self._dispatch.shutdown(wait=False, cancel_futures=True)
        for lane in self._lanes:
            lane.close()

    def submit(self, study: dict, session_pk: int, seed: int, domain: str,
               responses: list[dict], served: list[list] | None = None, *,
               urgent: bool = True) -> Future:
        """The decision after `responses` (stored events are append-only, so their count
        names them); submitted once, and again only if it failed. `urgent`: a page waits
        for it (an ahead decision is not urgent until a page asks for it). `served`: the
        stored items the responses answer, checked against the teacher's replay."""
        key = (study["version"], session_pk, domain, len(responses))
        with self._lock:
            fut = self._futures.get(key)
            if fut is not None and not (fut.done() and fut.exception() is not None):
                if urgent:
                    self._lane(session_pk).promote(fut)
                return fut
            fut = self._run(session_pk,
                            self._job(study, session_pk, seed, domain, responses, served),
                            urgent=urgent)
            self._futures[key] = fut
            if len(self._futures) > MAX_FUTURES:
                for k in [k for k, f in self._futures.items() if f.done()][: MAX_FUTURES // 2]:
                    del self._futures[k]

        def ahead(out: dict) -> None:
            # after a demonstration or feedback the response is known ({}): decide the item
            # after it now, in the same worker, so answering it finds the decision ready
            more = None if served is None else [*served, [out["kind"], out["demo"]]]
            self.submit(study, session_pk, seed, domain, [*responses, {}], more, urgent=False)

        def done(f: Future) -> None:
            if f.cancelled() or f.exception() is not None:
                return
            out = f.result()
            if out is not None and out.get("kind", "test") != "test":
                with contextlib.suppress(RuntimeError):  # shutting down
                    self._dispatch.submit(ahead, out)

        fut.add_done_callback(done)
        return fut

    def _job(self, study: dict, session_pk: int, seed: int, domain: str,
             responses: list[dict], served: list[list] | None) -> tuple[Callable, tuple]:
        if self.workers <= 0:
            return _decide, (self.live, study, session_pk, seed, domain, responses, served)
        return decide_job, (slim_study(study, domain), session_pk, seed, domain, responses,
                            served)

    def _lane(self, session_pk: int) -> DecisionLane:
        return self._lanes[session_pk % len(self._lanes)]

    def _run(self, session_pk: int, job: tuple[Callable, tuple], *, urgent: bool) -> Future:
        """Queue on the session's worker (its lane replaces a worker that died)."""
        fn, args = job
        return self._lane(session_pk).put(fn, args, urgent=urgent)

    def heal(self, fut: Future) -> None:
        """Replace the worker a failed future ran in if it is broken."""
        exc = fut.exception() if fut.done() and not fut.cancelled() else None
        if isinstance(exc, BrokenProcessPool):
            for lane in self._lanes:
                lane.heal()


def result_or_none(fut: Future, timeout: float) -> tuple[bool, Any]:
    """(finished, result) after waiting up to `timeout` s; a failed decision counts as
    unfinished (it is submitted again on the next read)."""
    try:
        return True, fut.result(timeout=max(0.0, timeout))
    except TimeoutError:
        return False, None
    except Exception:  # noqa: BLE001 - a worker's failure: retried on the next read
        return False, None


async def result_or_none_async(fut: Future, timeout: float) -> tuple[bool, Any]:
    """`result_or_none` for the event loop, holding no thread while it waits.

    A decision that has already finished is taken at once: `asyncio.wait_for` of a
    wrapped future with a timeout of 0 always times out (the wrapper only learns the
    result on the loop's next turn), so a page polling with ``wait=0`` would never
    record a decision that missed its event's short wait, and stay "preparing"."""
    if fut.done():
        return result_or_none(fut, 0.0)
    try:
        out = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(fut)),
                                     max(0.0, timeout))
    except Exception:  # noqa: BLE001 - not ready in time, or failed: retried later
        return False, None
    return True, out
