"""The study server never closes an idle connection first (the cause of the connection
resets seen with two servers behind a round-robin client: docs/study.md, "Several server
processes").

A client's idle clock starts when it reads a reply; the server's when it sends it. A client
that reads a reply late (a busy machine) and reuses the connection within its own idle
limit must still be answered, not reset."""

from __future__ import annotations

import socket
import time

from fastapi import FastAPI

from cfteach.study.livesrv import KEEP_ALIVE_S, running

REQUEST = b"GET /ping HTTP/1.1\r\nHost: test\r\n\r\n"


def _status(data: bytes) -> bytes:
    return data.split(b"\r\n", 1)[0]


def test_a_late_read_reply_leaves_the_connection_usable() -> None:
    app = FastAPI()

    @app.get("/ping")
    def ping() -> dict:
        return {"ok": True}

    with running(app) as base:
        port = int(base.rsplit(":", 1)[1])
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(REQUEST)
            time.sleep(5.5)  # the reply waits unread past uvicorn's default 5 s keep-alive
            assert _status(s.recv(65536)) == b"HTTP/1.1 200 OK"
            time.sleep(0.5)  # well inside a client's idle limit (httpx: 5 s)
            s.sendall(REQUEST)
            assert _status(s.recv(65536)) == b"HTTP/1.1 200 OK"  # not b"" (closed) or reset


def test_keep_alive_outlasts_common_proxies() -> None:
    assert KEEP_ALIVE_S > 60  # nginx's upstream keepalive_timeout, browsers' idle limits
