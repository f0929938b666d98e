"""Playable games: the reachable part of one MDP instance as a transition table.

The browser plays from this table (so it needs no domain code) and the server scores a
submitted move list by replaying it in the same table, which was built with the domain's
own `Instance.step`. Feature vectors stay on the server: the page never sees rewards.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from cfteach.jsonable import to_jsonable

MAX_GAME_STATES = 20_000


class ScoringError(ValueError):
    """A submitted move list cannot be replayed (unknown action, unfinished, too long)."""


def build_game(instance: Any, start_state: Any, actions: tuple[str, ...]) -> dict:
    """Breadth-first table of every state reachable from `start_state`.

    Returns `states` (JSON states, the start first), `next[s][a]` (state index; `None` for
    terminal states, which are absorbing), `terminal[s]` and `phi[s][a]` (feature vector).
    """
    key = instance.state_to_json
    # Nodes are (state, terminal): an action that ends the episode without changing the
    # state tuple (e.g. a declared `exit`) reaches a terminal node of its own, never marking
    # the state it left as terminal.
    index: dict[Any, int] = {(start_state, False): 0}
    order = [start_state]
    terminal = [False]
    nxt: list[list[int] | None] = []
    phi: list[list[list[float]] | None] = []
    queue = deque([0])
    rows: dict[int, tuple[list[int], list[list[float]]]] = {}
    while queue:
        i = queue.popleft()
        s = order[i]
        if terminal[i]:
            continue
        succ, feats = [], []
        for a in range(len(actions)):
            s2, f, term = instance.step(s, a)
            node = (s2, bool(term))
            if node not in index:
                if len(order) >= MAX_GAME_STATES:
                    raise ValueError(f"game has more than {MAX_GAME_STATES} reachable states")
                index[node] = len(order)
                order.append(s2)
                terminal.append(bool(term))
                queue.append(index[node])
            succ.append(index[node])
            feats.append([float(x) for x in np.asarray(f).ravel()])
        rows[i] = (succ, feats)
    for i in range(len(order)):
        if i in rows and not terminal[i]:
            nxt.append(rows[i][0])
            phi.append(rows[i][1])
        else:
            nxt.append(None)
            phi.append(None)
    return {
        "actions": list(actions),
        "states": [to_jsonable(key(s)) for s in order],
        "next": nxt,
        "terminal": terminal,
        "phi": phi,
    }


def public_game(game: dict) -> dict:
    """The part of a game the browser may see (no features)."""
    return {k: game[k] for k in ("actions", "states", "next", "terminal")}


@dataclass(frozen=True)
class Score:
    """Outcome of replaying a move list."""

    reward: float
    feature_counts: list[float]
    n_actions: int
    final_state: int
    finished: bool


def replay(game: dict, weights: list[float], actions: list[str], *, require_end: bool = True,
           max_actions: int = 500) -> Score:
    """Replay `actions` from the game's start and sum `w . phi` along the way."""
    if len(actions) > max_actions:
        raise ScoringError(f"too many actions ({len(actions)} > {max_actions})")
    names = game["actions"]
    w = np.asarray(weights, dtype=float)
    mu = np.zeros(len(w))
    s = 0
    for t, name in enumerate(actions):
        if name not in names:
            raise ScoringError(f"unknown action {name!r} at position {t}; expected one of {names}")
        if game["terminal"][s]:
            raise ScoringError(f"action {name!r} at position {t} comes after the game ended")
        a = names.index(name)
        mu += np.asarray(game["phi"][s][a], dtype=float)
        s = game["next"][s][a]
    finished = bool(game["terminal"][s])
    if require_end and not finished:
        raise ScoringError("the move list does not reach the end of the game")
    return Score(float(w @ mu), mu.tolist(), len(actions), s, finished)


def optimal_value(game: dict, weights: list[float], *, max_sweeps: int = 10_000) -> float:
    """Best achievable total reward from the start to a terminal state (value iteration).

    Used for the practice game, whose target energy is computed, not typed in.
    """
    nxt, rew, term = _arrays(game, weights)
    return float(_values(nxt, rew, term, max_sweeps)[0])


def _arrays(game: dict, weights: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Successor and reward arrays; terminal rows loop on themselves with reward 0."""
    n, na = len(game["states"]), len(game["actions"])
    w = np.asarray(weights, dtype=float)
    nxt = np.tile(np.arange(n)[:, None], (1, na))
    rew = np.zeros((n, na))
    term = np.asarray(game["terminal"], dtype=bool)
    for i in np.flatnonzero(~term):
        nxt[i] = game["next"][i]
        rew[i] = np.asarray(game["phi"][i], dtype=float) @ w
    return nxt, rew, term


def _values(nxt: np.ndarray, rew: np.ndarray, term: np.ndarray, max_sweeps: int) -> np.ndarray:
    v = np.where(term, 0.0, -np.inf)
    for _ in range(max_sweeps):
        new = np.where(term, 0.0, (rew + v[nxt]).max(axis=1))
        if np.array_equal(new, v):
            return v
        v = new
    raise ValueError("value iteration did not converge (a reward-gaining cycle?)")


def best_path(game: dict, weights: list[float]) -> list[str]:
    """An action list with the highest total reward (first best action in action order)."""
    nxt, rew, term = _arrays(game, weights)
    v = _values(nxt, rew, term, 10_000)
    path, s = [], 0
    while not term[s]:
        a = int(np.argmax(rew[s] + v[nxt[s]]))
        path.append(game["actions"][a])
        s = int(nxt[s, a])
        if len(path) > len(term):
            raise ValueError("no finite best path")
    return path


def shortest_path(game: dict) -> list[str]:
    """Fewest actions to the end, from the public table alone (what a naive player does)."""
    prev: dict[int, tuple[int, int]] = {0: (-1, -1)}
    queue = deque([0])
    while queue:
        s = queue.popleft()
        if game["terminal"][s]:
            path = []
            while prev[s][0] >= 0:
                s, a = prev[s]
                path.append(game["actions"][a])
            return path[::-1]
        for a, j in enumerate(game["next"][s]):
            if j not in prev:
                prev[j] = (s, a)
                queue.append(j)
    raise ValueError("the game cannot be finished")
