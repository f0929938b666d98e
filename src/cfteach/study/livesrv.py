"""Run the study app: the uvicorn settings every runner shares (`cfteach serve`, tests,
benchmarks), a free loopback port in a background thread, or `cfteach serve` in a child
process."""

from __future__ import annotations

import gc
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import uvicorn
from fastapi import FastAPI

#: Seconds uvicorn keeps an idle connection open. Longer than any client or proxy keeps
#: one idle (nginx's upstream `keepalive_timeout` 60 s; browsers ~60 s), so the other side
#: always closes first. A server that closes first races the client's next request on that
#: connection, which is then reset: the client's idle clock starts when it reads a reply,
#: the server's when it sends it, so a client that reads late (a busy machine) reuses a
#: connection the server has just closed (docs/study.md, "Several servers").
KEEP_ALIVE_S = 75


def settle_heap() -> None:
    """Exclude everything built so far (the study, its lesson pools) from garbage collection.

    A server or decision worker holds millions of long-lived objects from its start. Each
    full collection walked all of them, stopping every thread of the process: under 200
    participants a study server spent 2.5 s in 10 full collections, up to 1.1 s each
    (docs/study.md, "Load"). Frozen objects are still freed when nothing refers to them;
    only reference cycles among them would stay, and start-up data lives as long as the
    process anyway."""
    gc.collect()
    gc.freeze()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def server_config(app: FastAPI, *, host: str, port: int, forwarded_allow_ips: str = "",
                  log_level: str = "warning") -> uvicorn.Config:
    """uvicorn settings for the study app.

    `X-Forwarded-For` is believed only from the proxies in `forwarded_allow_ips`
    (comma-separated addresses or networks, `*` = any; uvicorn's ProxyHeadersMiddleware does
    the parsing). The default is no proxy at all: uvicorn alone would trust loopback, and
    then anything on the machine could pose as any number of clients to the rate limits.
    """
    trusted = forwarded_allow_ips.strip()
    return uvicorn.Config(app, host=host, port=port, log_level=log_level, access_log=False,
                          lifespan="off", proxy_headers=bool(trusted),
                          timeout_keep_alive=KEEP_ALIVE_S,
                          forwarded_allow_ips=trusted or None)


@contextmanager
def running(app: FastAPI, *, port: int | None = None,
            forwarded_allow_ips: str = "") -> Iterator[str]:
    """Yield the base URL (http://127.0.0.1:PORT) while uvicorn serves `app`."""
    port = port or free_port()
    config = server_config(app, host="127.0.0.1", port=port,
                           forwarded_allow_ips=forwarded_allow_ips)
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            raise RuntimeError("study server did not start")
        time.sleep(0.02)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=10)


@contextmanager
def serving_process(study: str | Path, *args: str,
                    timeout: float = 60.0) -> Iterator[tuple[str, subprocess.Popen]]:
    """Run `cfteach serve --study STUDY ARGS...` on a free loopback port in a child process
    (its memory is then its own, measurable); yield the base URL and the process."""
    import httpx  # a test and benchmark dependency only
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-c", "from cfteach.cli import main; main()", "serve", "--study",
         str(study), "--host", "127.0.0.1", "--port", str(port), *args],
        env={**os.environ, "CFTEACH_LOG": "warning"},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + timeout
        while True:
            if proc.poll() is not None:
                err = proc.stderr.read() if proc.stderr else ""
                raise RuntimeError(f"cfteach serve exited: {err[-2000:]}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"cfteach serve did not start within {timeout:.0f} s")
            try:
                if httpx.get(base + "/", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.1)
        yield base, proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
