"""Raw-socket probes of a running study server, for the tests and bench scripts that check
what an HTTP client library would not send (a chunked body of any size) and what it costs
the server (its peak memory)."""

from __future__ import annotations

import select
import socket
import time
from dataclasses import dataclass
from pathlib import Path


@dataclass
class ChunkedResult:
    """What came back: the status line's code (0 if none) and how many body bytes went out."""

    status: int
    sent: int
    response: bytes


def post_chunked(host: str, port: int, path: str, total: int, *, chunk: int = 16 * 1024,
                 content_type: str = "application/json", timeout: float = 30.0,
                 finish: bool = True) -> ChunkedResult:
    """POST `total` bytes with `Transfer-Encoding: chunked` (no Content-Length).

    Stops sending as soon as the server answers (a server that refuses a body early should
    not have to take the rest); with `finish=False` the body is never terminated, so only a
    server that answers before the end of the body answers at all (within `timeout`).
    """
    deadline = time.monotonic() + timeout
    sent = 0
    with socket.create_connection((host, port), timeout=timeout) as s:
        s.sendall(f"POST {path} HTTP/1.1\r\nHost: {host}:{port}\r\n"
                  f"Content-Type: {content_type}\r\nTransfer-Encoding: chunked\r\n\r\n".encode())
        piece = b"a" * chunk
        try:
            while sent < total and not _readable(s):
                n = min(chunk, total - sent)
                s.sendall(f"{n:x}\r\n".encode() + piece[:n] + b"\r\n")
                sent += n
            if finish and not _readable(s):
                s.sendall(b"0\r\n\r\n")
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed; read what it said
        response = _read_response(s, deadline)
    status = int(response.split(b" ", 2)[1]) if response.startswith(b"HTTP/") else 0
    return ChunkedResult(status, sent, response)


def _readable(s: socket.socket) -> bool:
    return bool(select.select([s], [], [], 0)[0])


def _read_response(s: socket.socket, deadline: float) -> bytes:
    """Status line, headers and (by Content-Length) body; what arrived by `deadline`."""
    data = b""
    while time.monotonic() < deadline:
        head, sep, body = data.partition(b"\r\n\r\n")
        if sep:
            length = next((int(line.split(b":", 1)[1]) for line in head.split(b"\r\n")
                           if line.lower().startswith(b"content-length:")), 0)
            if len(body) >= length:
                break
        s.settimeout(max(0.01, deadline - time.monotonic()))
        try:
            part = s.recv(65536)
        except (TimeoutError, ConnectionResetError):
            break
        if not part:
            break
        data += part
    return data


def peak_rss_mb(pid: int) -> float:
    """The process's peak resident set size so far (VmHWM, Linux), in MiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"no VmHWM for process {pid}")
