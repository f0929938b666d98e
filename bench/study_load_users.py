"""Locust participants for bench_study_load.py: the study bot, paced like a person.

Importing this module imports Locust, which monkey-patches the standard library for gevent
(sockets, `time.sleep`): import it before anything that opens connections.

Each simulated participant is `cfteach.study.bot.run_participant` (consent to completion,
the same walk the tests use) talking through Locust's HTTP client, with a think time before
every event so one participant sends one event per `pace` seconds on average. After the
deadline no new event is sent: a participant stops between requests, never inside one, so
every event the server stored was either acknowledged to us or is counted as in flight.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass, field
from typing import Any

from locust import FastHttpUser, constant, task  # noqa: I001  (imported first: gevent)
from locust.exception import StopUser

from cfteach.study.bot import BotError, run_participant


@dataclass
class Tally:
    """What the participants saw; read by the bench after the run."""

    acked: dict[str, int] = field(default_factory=dict)  # participant id -> events got 200
    in_flight: dict[str, int] = field(default_factory=dict)  # events sent, never answered
    completed: list[str] = field(default_factory=list)  # participant ids that finished
    started: int = 0
    failures: list[str] = field(default_factory=list)  # non-200 answers and other errors


class Plan:
    """Run settings shared by all participants (set by the bench before spawning)."""

    pace = 2.0  # mean seconds between two events of one participant
    deadline = float("inf")  # time.monotonic() after which no new event is sent
    tally = Tally()


class PacedClient:
    """What `run_participant` needs (`get`, `post`), over Locust's client, with think time.

    Records acknowledged events per participant and waits before each event so that events
    leave at the participant's pace (a slow answer eats into the next think time).
    """

    def __init__(self, locust_client: Any, rng: random.Random) -> None:
        self.client, self.rng = locust_client, rng
        self.pid: str | None = None
        self.next_at = time.monotonic() + rng.uniform(0, Plan.pace)  # spread the starts

    def get(self, url: str, **kw: Any) -> Any:
        return self._send("GET", url, **kw)

    def post(self, url: str, **kw: Any) -> Any:
        if url != "/api/event":
            return self._send("POST", url, **kw)
        now = time.monotonic()
        if max(now, self.next_at) >= Plan.deadline:
            raise StopUser()
        if self.next_at > now:
            time.sleep(self.next_at - now)  # gevent's sleep: other participants run
        sent = time.monotonic()
        # Think time: uniform around the pace (people are not metronomes), mean = pace.
        self.next_at = sent + self.rng.uniform(0.5, 1.5) * Plan.pace
        tally = Plan.tally
        tally.in_flight[self.pid] = tally.in_flight.get(self.pid, 0) + 1
        r = self._send("POST", url, **kw)
        if r.status_code:  # an HTTP answer (0: connection lost, maybe stored: stays counted)
            tally.in_flight[self.pid] -= 1
        if r.status_code == 200:
            tally.acked[self.pid] = tally.acked.get(self.pid, 0) + 1
        return r

    def _send(self, method: str, url: str, **kw: Any) -> Any:
        r = self.client.request(method, url, name=f"{method} {url}", **kw)
        if r.status_code != 200:
            Plan.tally.failures.append(f"{method} {url} -> {r.status_code}: {r.text[:200]}")
        elif url == "/api/session":
            self.pid = r.json()["participant_id"]
            Plan.tally.acked.setdefault(self.pid, 0)
            Plan.tally.started += 1
        return r


class Participant(FastHttpUser):
    """One browser tab after another: each task is one whole participant."""

    wait_time = constant(0)
    network_timeout = connection_timeout = 60.0
    _counter = 0

    @task
    def take_part(self) -> None:
        Participant._counter += 1
        n = Participant._counter
        client = PacedClient(self.client, random.Random(n))
        try:
            out = run_participant(client, {"prolific_pid": f"LOAD{n:06d}", "study_id": "B"},
                                  rng=random.Random(n))
        except StopUser:
            raise
        except BotError:
            return  # a refused request: already counted in `failures` by PacedClient
        except Exception as e:  # noqa: BLE001  (counted, and the next participant starts)
            Plan.tally.failures.append(f"participant {client.pid}: {e!r}")
            return
        if out["state"]["step"]["kind"] == "complete":
            Plan.tally.completed.append(client.pid)
        else:
            Plan.tally.failures.append(f"participant {client.pid} ended on "
                                       f"{out['state']['step']['kind']}")
