"""Decision worker processes end when their server is killed outright (SIGKILL, out of
memory): nothing else would stop an idle worker, which holds its lesson pools' memory."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SERVER = """
import sys, time
from cfteach.study.decisions import Decider
from cfteach.study.live import LiveTeaching
d = Decider(LiveTeaching(), [], 1)
print(*d._executors[0]._processes, flush=True)
time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited (its new parent reaps it)


def test_workers_end_when_their_server_is_killed() -> None:
    server = subprocess.Popen([sys.executable, "-c", SERVER], stdout=subprocess.PIPE, text=True)
    try:
        workers = [int(p) for p in server.stdout.readline().split()]  # type: ignore[union-attr]
        assert workers and all(_alive(p) for p in workers)
    finally:
        server.send_signal(signal.SIGKILL)
        server.wait()
    deadline = time.monotonic() + 30
    while any(_alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = [p for p in workers if _alive(p)]
    for p in left:  # do not leave them behind if the check failed
        os.kill(p, signal.SIGKILL)
    assert left == []


def test_workers_decide_at_a_lower_os_priority() -> None:
    """Decisions yield the CPU to the web server: on a saturated machine the server's
    events and page reads are served first and decisions wait (docs/study.md, "Load")."""
    from cfteach.study.decisions import Decider
    from cfteach.study.live import LiveTeaching

    d = Decider(LiveTeaching(), [], 1)
    try:
        worker = d._executors[0].submit(os.nice, 0).result(timeout=120)
    finally:
        d.close()
    server = os.nice(0)
    assert worker > server or server == 19


def _blas_threads() -> list[int]:
    from threadpoolctl import threadpool_info

    return [int(p["num_threads"]) for p in threadpool_info() if p["user_api"] == "blas"]


def test_workers_run_blas_on_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """Idle OpenBLAS threads spin: with one per core in every worker, decisions cost ~10x
    their CPU (docs/study.md, "Load"). Asked for 4 threads by the environment, as a
    four-core machine would give them, each worker still runs BLAS on one."""
    from cfteach.study.decisions import WORKER_BLAS_THREADS, Decider
    from cfteach.study.live import LiveTeaching

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")  # inherited by the spawned workers
    d = Decider(LiveTeaching(), [], 1)
    try:
        threads = d._executors[0].submit(_blas_threads).result(timeout=120)
    finally:
        d.close()
    assert threads, "numpy's BLAS not found in the worker"
    assert threads == [WORKER_BLAS_THREADS] * len(threads)


def test_workers_keep_their_start_up_objects_out_of_garbage_collection() -> None:
    """A full collection in a worker would walk every lesson pool built at its start,
    stopping the decision it interrupts (docs/study.md, "Load"): start-up objects are frozen."""
    import gc

    from cfteach.study.decisions import Decider
    from cfteach.study.live import LiveTeaching

    d = Decider(LiveTeaching(), [], 1)
    try:
        frozen = d._executors[0].submit(gc.get_freeze_count).result(timeout=120)
    finally:
        d.close()
    assert frozen > 1000


def test_settle_heap_freezes_what_exists_and_new_objects_stay_collectable() -> None:
    import gc
    import weakref

    from cfteach.study.livesrv import settle_heap

    assert gc.get_freeze_count() == 0
    try:
        settle_heap()
        frozen = gc.get_freeze_count()
        assert frozen > 1000

        class Node:
            pass

        a, b = Node(), Node()
        a.other, b.other = b, a  # a cycle made after the freeze is still collected
        gone = weakref.ref(a)
        del a, b
        gc.collect()
        assert gone() is None
    finally:
        gc.unfreeze()
