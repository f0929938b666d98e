"""The items of a closed-loop session and how a test answer is scored.

`Item` is one step of the conversation (what is shown, and why); `score_answer` replays a
test answer from the test's start and scores it as the study does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from cfteach.closedloop.pool import LessonPool
from cfteach.mdp.scoring import optimal_mask
from cfteach.teaching.records import demo_json

__all__ = ["KINDS", "Item", "Outcome", "score_answer"]

KINDS = ("demonstration", "test", "feedback")


@dataclass(frozen=True)
class Item:
    """One step of the conversation.

    `kind`: ``demonstration`` (purpose ``lesson`` or ``remedial``), ``test`` (``diagnostic``)
    or ``feedback``. `demo`: the DemoSet index shown (for a test: its start; for feedback:
    the optimal answer from the failed test's start). `about`: for a diagnostic test the
    lesson's item index, for feedback and remedial lessons the failed test's item index.
    `answer`: for feedback, the learner's answer to that test (as observed).
    """

    index: int
    kind: str
    purpose: str
    demo: int
    about: int | None = None
    answer: dict[str, Any] | None = None
    predicted_optimal: float | None = None  # belief's P(optimal) for a test, when chosen
    gain: float | None = None               # share of the belief a lesson would cut

    def to_json(self, pool: LessonPool) -> dict[str, Any]:
        """What a learner (or the study page) is shown, plus the bookkeeping fields."""
        shown = demo_json(pool.ds, self.demo)
        if self.kind == "test":
            shown = {k: shown[k] for k in ("env_code", "env_index", "start_state")}
            shown["optimal_reward"] = pool.ds.reward(self.demo)
        out = {"index": self.index, "kind": self.kind, "purpose": self.purpose,
               "demo": self.demo, "about": self.about, **shown}
        if self.answer is not None:
            out["answer"] = self.answer
        if self.predicted_optimal is not None:
            out["predicted_optimal"] = self.predicted_optimal
        if self.gain is not None:
            out["gain"] = self.gain
        return out


@dataclass
class Outcome:
    """A scored test answer (what the teacher's belief is updated with)."""

    correct: bool
    finished: bool
    mu: np.ndarray
    states: list[int] | None = None   # visited before each move (when moves were given)
    actions: list[int] | None = None


def score_answer(pool: LessonPool, d: int, response: dict[str, Any]) -> Outcome:
    """Replay a test answer from the test's start and score it as the study does (M1)."""
    ds = pool.ds
    b = ds.batch
    e = int(ds.env[d])
    states: list[int] | None = None   # the moves, when given
    actions: list[int] | None = None
    if "actions" in response:
        s = int(ds.start[d])
        mu = np.zeros(ds.F)
        states, actions = [], []
        for t, name in enumerate(response["actions"]):
            if name not in b.actions:
                raise ValueError(f"test answer: unknown action {name!r} at step {t} "
                                 f"(actions: {', '.join(b.actions)})")
            if s == b.sink:
                raise ValueError(f"test answer continues after the end (step {t})")
            a = b.actions.index(name)
            states.append(s)
            actions.append(a)
            mu += b.features[e, s, a]
            s = int(b.next_state[e, s, a])
        finished = s == b.sink
    elif "feature_counts" in response:
        mu = np.asarray(response["feature_counts"], dtype=float)
        if mu.shape != (ds.F,):
            raise ValueError(f"test answer: feature_counts needs {ds.F} numbers, "
                             f"got {response['feature_counts']!r}")
        finished = bool(response.get("finished", True))
    else:
        raise ValueError("a test answer needs 'actions' or 'feature_counts'")
    reward = float(ds.weights @ mu)
    correct = bool(optimal_mask(np.asarray(reward), ds.reward(d), finished))
    return Outcome(correct, finished, mu, states, actions)
