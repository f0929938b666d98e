"""A simulated participant that walks the whole study through the HTTP API.

Used by the tests and by `bench/bench_study_load.py`; `client` is anything with httpx's
`get`/`post` (an `httpx.Client` on a live server or FastAPI's `TestClient`).
"""

from __future__ import annotations

import random
import time
import uuid
from typing import Any

from .games import best_path, shortest_path
from .steps import demo_required_ms


class BotError(RuntimeError):
    pass


def run_participant(client: Any, params: dict | None, *, study: dict | None = None,
                    rng: random.Random | None = None, stop_after: int | None = None,
                    fail_practice: bool = False, token: str | None = None,
                    comment: str = "") -> dict:
    """Go from consent to completion; returns the final state and what was answered.

    With `study` (the server's study.json) the bot plays tests optimally; without it, it
    takes the shortest way to the end. `stop_after` stops after that many advancing steps.
    `comment` is typed into every free-text box (each survey's with its domain appended).
    Each demonstration is "watched" for as long as the server requires (its steps x the
    study's `demo_step_ms`, minus the tolerance), so studies made with a small
    `--demo-step-ms` keep bots fast.
    """
    rng = rng or random.Random(0)
    if token is None:
        r = client.post("/api/session", json=params)
        _ok(r)
        token = r.json()["token"]
    headers = {"X-Session-Token": token}
    answers: dict[str, Any] = {"token": token, "tests": [], "likert": [], "events": 0}

    def send(step: int, type_: str, payload: dict) -> dict:
        resp = client.post("/api/event", headers=headers, json={
            "event_id": uuid.uuid4().hex, "step_index": step, "type": type_,
            "payload": payload})
        _ok(resp)
        answers["events"] += 1
        return resp.json()

    st = _state(client, headers)
    advanced = 0
    while st["status"] == "in_progress" and st["step"]["kind"] != "complete":
        if stop_after is not None and advanced >= stop_after:
            break
        i, s = st["step_index"], st["step"]
        kind = s["kind"]
        if kind == "consent":
            out = send(i, "consent", {"adult": True, "read": True, "agree": True})
        elif kind == "practice":
            moves = best_path(s["game"], s["weights"])
            if fail_practice:
                moves = _detour(s["game"]) + moves
            out = send(i, "practice_attempt", {"actions": moves, "time_ms": 1000})
        elif kind == "demos":
            for k in range(len(s["demos"])):
                if s["completed"][k] < 1:
                    need = demo_required_ms(len(s["demos"][k]["actions"]), s["step_ms"])
                    send(i, "demo_play_start", {"demo_index": k})
                    t0 = time.monotonic()
                    time.sleep(need / 1000)
                    send(i, "demo_play_end", {"demo_index": k, "completed": True,
                                              "watch_ms": round(1000 * (time.monotonic() - t0))})
            out = send(i, "continue", {})
        elif kind == "closed_loop" and s.get("preparing"):
            # the next item is being decided: wait for it as the page does
            st = _state(client, headers, wait=2.0)
            continue
        elif kind == "closed_loop":
            item = s["item"]
            k = item["position"]
            if item["kind"] != "test" and item["completed"] < 1:
                need = demo_required_ms(item["n_actions"], s["step_ms"])
                send(i, "demo_play_start", {"demo_index": k})
                t0 = time.monotonic()
                time.sleep(need / 1000)
                send(i, "demo_play_end", {"demo_index": k, "completed": True,
                                          "watch_ms": round(1000 * (time.monotonic() - t0))})
            body: dict[str, Any] = {"item": k}
            if item["kind"] == "test":  # the naive player: often wrong, so feedback follows
                body.update(actions=shortest_path(item["game"]), time_ms=1000)
            answers.setdefault("closed_loop", []).append((s["domain"], k, item["kind"]))
            out = send(i, "item_done", body)
        elif kind == "survey":
            inf, eff = rng.randint(1, 5), rng.randint(1, 5)
            answers["likert"].append((s["domain"], inf, eff))
            out = send(i, "likert", {"informativeness": inf, "mental_effort": eff,
                                     "comment": f"{comment} {s['domain']}" if comment else ""})
        elif kind == "test":
            if study is not None:
                t = find_test(study, s)
                moves = best_path(t["game"], study["domain_info"][s["domain"]]["weights"])
            else:
                moves = shortest_path(s["game"])
            conf = rng.randint(1, 5)
            answers["tests"].append((s["domain"], s["trial"], moves, conf))
            out = send(i, "test_response", {"actions": moves, "time_ms": 1234,
                                            "confidence": conf})
        elif kind == "demographics":
            out = send(i, "demographics", {"age": 30, "gender": "Female",
                                           "education": "High school", "comments": comment})
        else:
            out = send(i, "continue", {})
        st = out["state"]
        advanced += 1
    answers["state"] = st
    return answers


def _state(client: Any, headers: dict, wait: float = 0.0) -> dict:
    r = client.get("/api/state", headers=headers,
                   **({"params": {"wait": wait}} if wait else {}))
    _ok(r)
    return r.json()


def _detour(game: dict) -> list[str]:
    """Two moves that leave the start and come back: a wasted 10% of practice energy."""
    acts = game["actions"]
    for a, b in (("up", "down"), ("down", "up"), ("left", "right"), ("right", "left")):
        j = game["next"][0][acts.index(a)]
        if j != 0 and not game["terminal"][j] and game["next"][j][acts.index(b)] == 0:
            return [a, b]
    raise BotError("no detour possible from the practice start")


def find_test(study: dict, s: dict) -> dict:
    """The study's test shown on test page `s` (the page does not name it: bots only)."""
    for test_set in study["tests"][s["domain"]]:
        for t in test_set:
            if t["game"]["states"] == s["game"]["states"] and t["layout"] == s["layout"]:
                return t
    raise BotError("test not found in study")


def _ok(resp: Any) -> None:
    if resp.status_code != 200:
        raise BotError(f"{resp.request.method} {resp.request.url} -> {resp.status_code}: "
                       f"{resp.text[:300]}")
