"""Declared actions in the study app: keys and labels come from the domain's ActionSpecs and
the server stores and scores moves of a custom action (`exit` on "x")."""

from __future__ import annotations

import csv
import uuid
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from actions_fixtures import EXIT, ExitDomain
from cfteach.domains import ActionSpec
from cfteach.study import create_app, init_study
from cfteach.study.bot import run_participant
from cfteach.study.build import preview_sources
from cfteach.study.config import load_study
from cfteach.study.controls import controls
from cfteach.study.export import export_csv
from cfteach.study.games import build_game
from cfteach.study.layout import instance_layout

PARAMS = {"prolific_pid": "5f1c0ffee0ddba11c0ffee77", "study_id": "S1", "session_id": "X7"}


@pytest.fixture(scope="module")
def exit_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("exit_study")
    init_study(out, preview_sources([ExitDomain()], demos=2), demo_step_ms=10)
    return out


def _event(c: TestClient, token: str, step: int, type_: str, payload: dict):  # noqa: ANN202
    return c.post("/api/event", headers={"X-Session-Token": token}, json={
        "event_id": uuid.uuid4().hex, "step_index": step, "type": type_, "payload": payload})


def test_exit_reaches_a_terminal_node_of_its_own() -> None:
    dom = ExitDomain()
    inst = dom.instances()[0]
    game = build_game(inst, inst.initial_state, tuple(dom.actions))
    a = game["actions"].index("exit")
    end = game["next"][0][a]
    assert end != 0 and game["terminal"][end] and not game["terminal"][0]
    assert game["states"][end] == game["states"][0]  # same state tuple, but the game is over


def test_page_data_carries_the_declared_keys(exit_study: Path, tmp_path: Path) -> None:
    study = load_study(exit_study)
    info = study["domain_info"]["delivery_exit"]
    assert info["keys"][-1] == "exit"
    assert {"action": "exit", "key": "x", "key_label": "x", "label": "leave the game",
            "effect": "exit"} in info["controls"]
    app = create_app(exit_study, f"sqlite:///{tmp_path / 's.db'}")
    with TestClient(app) as c:
        token = c.post("/api/session", json=PARAMS).json()["token"]
        st = c.get("/api/state", headers={"X-Session-Token": token}).json()
        while st["step"]["kind"] != "test":
            st = run_participant(c, None, token=token, study=study, stop_after=1)["state"]
            if st["step"]["kind"] in ("practice", "free_play"):  # the built-in six there
                assert [k["key"] for k in st["step"]["controls"]] == [
                    "ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "p", "d"]
        assert st["step"]["info"]["controls"] == info["controls"]
        assert "exit" in st["step"]["game"]["actions"]
    app.state.service.engine.dispose()


def test_a_custom_action_is_stored_and_scored(exit_study: Path, tmp_path: Path) -> None:
    study = load_study(exit_study)
    db = f"sqlite:///{tmp_path / 's.db'}"
    app = create_app(exit_study, db)
    with TestClient(app) as c:
        token = c.post("/api/session", json=PARAMS).json()["token"]
        st = c.get("/api/state", headers={"X-Session-Token": token}).json()
        while st["step"]["kind"] != "test":
            st = run_participant(c, None, token=token, study=study, stop_after=1)["state"]
        i, game = st["step_index"], st["step"]["game"]
        # an answer the game has no action for, and a name the schema refuses
        bad = _event(c, token, i, "test_response", {"actions": ["jump"], "time_ms": 5,
                                                    "confidence": 3})
        assert bad.status_code == 422 and bad.json()["error"] == "bad_moves"
        bad = _event(c, token, i, "test_response", {"actions": ["ex it"], "time_ms": 5,
                                                    "confidence": 3})
        assert bad.status_code == 422
        # a detour, then exit: finished, stored, scored by the server, not optimal
        first = next(a for a in ("up", "down", "left", "right")
                     if game["next"][0][game["actions"].index(a)] != 0)
        moves = [first, "exit"]
        r = _event(c, token, i, "test_response", {"actions": moves, "time_ms": 5,
                                                  "confidence": 4})
        assert r.status_code == 200, r.text
    app.state.service.engine.dispose()
    export_csv(db, tmp_path / "export", include_previews=True)
    with open(tmp_path / "export" / "test_responses.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["actions"] for r in rows] == [" ".join(moves)]
    # the reward the domain's own step gives along the answer, under w*
    dom = ExitDomain()
    test = next(t for ts in study["tests"]["delivery_exit"] for t in ts
                if t["game"]["states"] == game["states"] and t["layout"] == st["step"]["layout"])
    inst = next(x for x in dom.instances()
                if instance_layout("delivery_exit", x) == st["step"]["layout"])
    s, mu = inst.state_from_json(game["states"][0]), 0.0
    for a in moves:
        s, phi, term = inst.step(s, dom.actions.index(a))
        mu = mu + phi
    assert term
    reward = float(dom.weights @ mu)
    assert float(rows[0]["reward"]) == pytest.approx(reward)
    assert float(rows[0]["optimal_reward"]) == pytest.approx(test["optimal_reward"])
    # optimal unless the detour was worth it (leaving the battery station pays)
    assert rows[0]["optimal"] == str(int(abs(reward - test["optimal_reward"]) < 1e-9))


def test_controls_refuse_the_reset_key_and_shared_keys() -> None:
    with pytest.raises(ValueError, match="resetting"):
        controls([ActionSpec("rest", "rest", "r", "stay")], what="d")
    with pytest.raises(ValueError, match="share the key"):
        controls([EXIT, ActionSpec("exit2", "leave", "X", "exit")], what="d")
    with pytest.raises(ValueError, match="cannot be used"):
        controls([ActionSpec("ex it", "leave", "q", "exit")], what="d")
