"""The closed-loop feedback page's content (`cfteach.study.feedback`), checked against an
independent replay of both answers with the domain's own `Instance.step`."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from cfteach.domains import load
from cfteach.study.feedback import energy_text, feedback_view
from cfteach.study.games import best_path, build_game, replay, shortest_path
from cfteach.study.texts import FEATURE_PHRASES, feature_phrase


def _independent(inst, actions: list[str], names: tuple[str, ...],  # noqa: ANN001
                 w: np.ndarray) -> tuple[float, np.ndarray, list]:
    """Reward, feature counts and states of `actions`, stepped with the domain itself."""
    s, states, mu = inst.initial_state, [inst.initial_state], np.zeros(len(w))
    for a in actions:
        s, phi, _ = inst.step(s, names.index(a))
        mu += np.asarray(phi, dtype=float)
        states.append(s)
    return float(w @ mu), mu, states


def _wrong_answers(game: dict, weights: list[float]) -> list[list[str]]:
    """Finished answers worse than the best: the fewest-steps route, and detours of one
    step out and back at the start followed by the best route."""
    best = best_path(game, weights)
    top = replay(game, weights, best).reward
    out: list[list[str]] = []
    candidates = [shortest_path(game)]
    for a, b in (("up", "down"), ("down", "up"), ("left", "right"), ("right", "left")):
        candidates.append([a, b, *best])
    for moves in candidates:
        try:
            r = replay(game, weights, moves).reward
        except Exception:  # noqa: BLE001 - a detour into a wall, say: not a candidate
            continue
        if r < top - 1e-9 and moves not in out:
            out.append(moves)
    return out


@pytest.mark.parametrize("name", ["delivery", "tiles", "skateboard"])
def test_feedback_numbers_match_the_domains_own_step(name: str) -> None:
    dom = load(name)
    w = np.asarray(dom.weights, dtype=float)
    names = tuple(dom.actions)
    rng = random.Random(7)
    insts = dom.instances()
    checked = 0
    for inst in rng.sample(insts, 4):
        game = build_game(inst, inst.initial_state, names)
        best = best_path(game, list(w))
        for wrong in _wrong_answers(game, list(w))[:3]:
            view = feedback_view(game, list(w), dom.feature_names, name, wrong, best)
            ra, mua, sa = _independent(inst, wrong, names, w)
            rb, mub, sb = _independent(inst, best, names, w)
            assert math.isclose(view["answer_energy"], ra, abs_tol=1e-9)
            assert math.isclose(view["best_energy"], rb, abs_tol=1e-9)
            assert view["answer_energy"] < view["best_energy"]
            # where they part: the first step whose state differs, and Chip's cell before it
            part = next(t for t in range(min(len(sa), len(sb))) if sa[t] != sb[t])
            assert view["part_step"] == part
            assert view["part_cell"] == list(inst.state_to_json(sa[part - 1])["agent"])
            # every feature whose count differs, with what the difference costs
            diff = {d["feature"]: d for d in view["differences"]}
            for i, f in enumerate(dom.feature_names):
                if math.isclose(mua[i], mub[i]):
                    assert f not in diff
                else:
                    assert diff[f]["answer"] == mua[i] and diff[f]["best"] == mub[i]
                    assert math.isclose(diff[f]["energy"], w[i] * (mua[i] - mub[i]))
            # the sentence names the costliest difference and its energy
            costs = w * (mua - mub)
            k = int(np.argmin(costs))
            assert costs[k] < 0
            assert FEATURE_PHRASES[name][dom.feature_names[k]] in view["sentence"]
            assert f"{energy_text(costs[k])} energy" in view["sentence"]
            n = round(abs(mua[k] - mub[k]))
            said = {1: "once", 2: "twice"}.get(n, f"{n} ") if mua[k] > mub[k] else \
                ("one time fewer" if n == 1 else f"{n} fewer")
            assert said in view["sentence"], view["sentence"]
            checked += 1
    assert checked >= 4


def test_energy_text_and_phrases() -> None:
    assert energy_text(-6) == "\u22126"
    assert energy_text(-0.5125 * 3) == "\u22121.54"
    assert energy_text(3.5) == "+3.5"
    assert energy_text(-1e-12) == "0"
    assert feature_phrase("my_domain", "hot_lava") == "counted \u201chot lava\u201d"
    # the built-in domains' phrases cover every feature they have
    for name, phrases in FEATURE_PHRASES.items():
        assert set(phrases) == set(load(name).feature_names)


def test_feedback_refuses_mismatched_weights() -> None:
    dom = load("tiles")
    inst = dom.instances()[0]
    game = build_game(inst, inst.initial_state, tuple(dom.actions))
    best = best_path(game, list(dom.weights))
    with pytest.raises(ValueError, match="features but 2 weights"):
        feedback_view(game, [1.0, 2.0], dom.feature_names, "tiles", best, best)
