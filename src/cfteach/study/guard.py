"""ASGI middleware in front of the study app: JSON-only API bodies, strict JSON (no NaN or
Infinity), a body size cap that holds for chunked bodies too, a time limit on receiving a
body, and the security headers every response carries."""

from __future__ import annotations

import asyncio
import json
import math

from starlette.types import ASGIApp, Message, Receive, Scope, Send

MAX_BODY = 64 * 1024
#: Seconds a client may take to send a request body (a half-sent body holds a connection).
BODY_TIMEOUT_S = 10.0
CSP = ("default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
       "connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'")
SECURITY_HEADERS = [
    (b"content-security-policy", CSP.encode()),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"cache-control", b"no-store"),
]
_BODY_METHODS = {"POST", "PUT", "PATCH"}


def is_json(content_type: str) -> bool:
    """True for `application/json`, with or without parameters (`; charset=utf-8`)."""
    return content_type.split(";", 1)[0].strip().lower() == "application/json"


class Guard:
    """Refuse bad bodies before the app sees them; add security headers to every response.

    The body is read here chunk by chunk, counting bytes, and refused with 413 as soon as it
    passes `max_body`, so a client that sends no Content-Length (chunked transfer) cannot
    make the server hold more than `max_body` plus one chunk in memory.
    """

    def __init__(self, app: ASGIApp, max_body: int = MAX_BODY,
                 body_timeout_s: float = BODY_TIMEOUT_S) -> None:
        self.app, self.max_body, self.body_timeout_s = app, max_body, body_timeout_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []),
                                                  *SECURITY_HEADERS]}
            await send(message)

        if scope["method"] in _BODY_METHODS:
            headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                       for k, v in scope.get("headers", [])}
            if scope["path"].startswith("/api/") and not is_json(headers.get("content-type", "")):
                await _refuse(send_with_headers, 415, "json_only",
                              "send the body as application/json", close=True)
                return
            declared = headers.get("content-length")
            if declared is not None and (not declared.isdigit() or int(declared) > self.max_body):
                await _refuse(send_with_headers, 413, "too_large",
                              f"request body over {self.max_body} bytes", close=True)
                return
            try:
                body = await asyncio.wait_for(self._read(receive), self.body_timeout_s)
            except _TooLarge:
                await _refuse(send_with_headers, 413, "too_large",
                              f"request body over {self.max_body} bytes", close=True)
                return
            except TimeoutError:
                await _refuse(send_with_headers, 408, "body_timeout", "request body not "
                              f"received within {self.body_timeout_s:g} s", close=True)
                return
            except _Gone:
                return
            if scope["path"].startswith("/api/") and (problem := _not_strict_json(body)):
                await _refuse(send_with_headers, 422, "bad_request", problem)
                return
            receive = _replay(body, receive)
        await self.app(scope, receive, send_with_headers)

    async def _read(self, receive: Receive) -> bytes:
        """The whole body; `_TooLarge` as soon as it passes `max_body` (the rest unread)."""
        parts: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":  # the client went away
                raise _Gone
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_body:
                raise _TooLarge
            parts.append(chunk)
            if not message.get("more_body", False):
                return b"".join(parts)


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON (numbers must be finite)")


def _finite(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"{text} is out of range (numbers must be finite)")
    return x


def _not_strict_json(body: bytes) -> str | None:
    """Why `body` is not strict JSON (NaN, Infinity, or a number that overflows to it), or
    None. Other syntax errors are left to the app's own parser and messages."""
    try:
        json.loads(body, parse_constant=_reject_constant, parse_float=_finite)
    except ValueError as e:
        msg = str(e)
        if "finite" in msg:
            return f"body: {msg}"
    except RecursionError:
        return None  # unreadable: the app's own parser answers 400, as for any bad JSON
    return None


class _TooLarge(Exception):
    pass


class _Gone(Exception):
    pass


def _replay(body: bytes, receive: Receive) -> Receive:
    """A `receive` that hands the app the body already read, then defers to the server."""
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()

    return replay


async def _refuse(send: Send, status: int, code: str, detail: str, *,
                  close: bool = False) -> None:
    """A JSON error; `close` (for a body left unread) ends the connection after it, so the
    server does not go on receiving a body nobody wants."""
    body = json.dumps({"error": code, "detail": detail}).encode()
    headers = [(b"content-type", b"application/json"),
               (b"content-length", str(len(body)).encode())]
    if close:
        headers.append((b"connection", b"close"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})
