"""Minari datasets of the robot's demonstrations and of people's test answers: they open with
`minari.load_dataset`, carry the right metadata, and replay step by step to the recorded
rewards in the registered `cfteach/...` environments (issue 15, part 2)."""

from __future__ import annotations

import csv
import json
import os
import random
from pathlib import Path

import minari
import numpy as np
import pytest
from typer.testing import CliRunner

from cfteach import domains, ecosystem
from cfteach.cli import app
from cfteach.ecosystem import minari_io


@pytest.fixture(autouse=True)
def minari_root(tmp_path, monkeypatch):
    """Every test writes its datasets under its own temp root (nothing is downloaded)."""
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def _bot_study(folder: Path, seed: int = 0) -> tuple[Path, Path]:
    from fastapi.testclient import TestClient

    from cfteach.study import create_app, export_csv, init_study, load_study
    from cfteach.study.bot import run_participant
    from cfteach.study.build import preview_sources

    # 10 ms a demonstration step: the bots watch every demonstration in real time
    init_study(folder / "study", preview_sources(seed=seed), completion_code="C1",
               demo_step_ms=10)
    db = f"sqlite:///{folder / 'study.db'}"
    study = load_study(folder / "study")
    with TestClient(create_app(folder / "study", db, researcher_token="t")) as client:
        for k in range(3):  # two play the tests optimally, one takes the shortest way
            run_participant(client, {"prolific_pid": f"5f1c0ffee0ddba11c0ffee{k:02d}",
                                     "study_id": "STUDY0c0ffee5f1", "session_id":
                                     f"SESSION0ddba11{k}"},
                            study=study if k != 1 else None, rng=random.Random(k))
    export_csv(db, folder / "export")
    return folder / "study", folder / "export"


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    return _bot_study(tmp_path_factory.mktemp("study"))


def _rows(export: Path, domain: str) -> list[dict]:
    with open(export / "test_responses.csv", newline="", encoding="utf-8") as f:
        return [r for r in csv.DictReader(f) if r["domain"] == domain]


def test_answers_open_with_minari_and_replay_to_the_exported_rewards(study):
    study_dir, export = study
    dom = domains.load("tiles")
    eps = ecosystem.answer_episodes(dom, study_dir, export)
    ecosystem.write_dataset(eps, "cfteach/tiles/answers-v0", dom)
    ds = minari.load_dataset("cfteach/tiles/answers-v0")  # the standard reader
    rows = _rows(export, "tiles")
    assert ds.total_episodes == len(rows) == 18
    assert ds.env_spec.id == "cfteach/Tiles-v0"
    metas = ecosystem.episode_metadata(ds)
    env = ds.recover_environment()
    optimal_seen = set()
    for ep, meta, row in zip(ds.iterate_episodes(), metas, rows, strict=True):
        assert (meta["participant_id"], meta["condition"], meta["test_id"]) == (
            row["participant_id"], row["condition"], row["test_id"])
        assert [dom.actions[a] for a in ep.actions] == row["actions"].split()
        # replay by hand in the recovered environment, step by step
        obs, _ = env.reset(options=dict(meta["options"]))
        assert np.array_equal(obs, ep.observations[0])
        total = 0.0
        for t, a in enumerate(ep.actions):
            obs, r, term, trunc, _ = env.step(int(a))
            assert np.array_equal(obs, ep.observations[t + 1])
            assert r == pytest.approx(float(ep.rewards[t]), abs=1e-12)
            assert term == bool(ep.terminations[t]) and not trunc
            total += r
        assert total == pytest.approx(float(row["reward"]), abs=1e-9)
        optimal_seen.add(int(meta["optimal"]))
    assert optimal_seen == {0, 1}  # the shortest-way bot is not always optimal
    assert ecosystem.check_replay(ds) == 18


def test_answers_carry_no_prolific_ids(study):
    study_dir, export = study
    dom = domains.load("skateboard")
    ds = ecosystem.write_dataset(ecosystem.answer_episodes(dom, study_dir, export),
                                 "cfteach/skateboard/answers-v0", dom)
    with open(export / "participants.csv", newline="", encoding="utf-8") as f:
        secret = {v for r in csv.DictReader(f)
                  for v in (r["prolific_pid"], r["study_id"], r["session_id"]) if v}
    assert secret
    stored = json.dumps([{k: str(v) for k, v in m.items()}
                         for m in ecosystem.episode_metadata(ds)])
    assert not any(s in stored for s in secret)
    data = b"".join(p.read_bytes() for p in Path(ds.storage.data_path).rglob("*")
                    if p.is_file())
    assert not any(s.encode() in data for s in secret)


def test_answers_keep_the_client_clock_when_the_export_has_it(study, tmp_path):
    study_dir, export = study
    with open(export / "test_responses.csv", newline="", encoding="utf-8") as f:
        rows = [{k: v for k, v in r.items() if k != "client_time_ms"}
                for r in csv.DictReader(f)]
    for name, extra in (("newer", True), ("older", False)):  # with and without the column
        folder = tmp_path / name
        folder.mkdir()
        (folder / "participants.csv").write_bytes((export / "participants.csv").read_bytes())
        with open(folder / "test_responses.csv", "w", newline="", encoding="utf-8") as f:
            w = csv.DictWriter(f, [*rows[0], *(["client_time_ms"] if extra else [])])
            w.writeheader()
            w.writerows({**r, **({"client_time_ms": 1000 + i} if extra else {})}
                        for i, r in enumerate(rows))
    eps = ecosystem.answer_episodes(domains.load("skateboard"), study_dir, tmp_path / "newer")
    want = [1000 + i for i, r in enumerate(rows) if r["domain"] == "skateboard"]
    assert [e.metadata["client_time_ms"] for e in eps] == want
    eps = ecosystem.answer_episodes(domains.load("skateboard"), study_dir, tmp_path / "older")
    assert "client_time_ms" not in eps[0].metadata


def test_answers_from_another_study_folder_are_refused(study, tmp_path):
    _, export = study
    other = _bot_study(tmp_path / "other", seed=1)[0]
    with pytest.raises(ValueError, match=r"participant .*test "):
        ecosystem.answer_episodes(domains.load("delivery"), other, export)


def test_curriculum_demonstrations_replay_to_their_rewards():
    from cfteach.study.build import preview_sources

    src = preview_sources(["delivery"], demos=3)[0]
    dom = src.domain
    eps = []
    for cur in src.curricula.values():
        eps += ecosystem.curriculum_episodes(dom, cur)
        assert [e.total_reward for e in eps[-3:]] == pytest.approx(
            [d["reward"] for d in cur["demos"]], abs=1e-9)
    ds = ecosystem.write_dataset(eps, "cfteach/delivery/curricula-v0", dom)
    assert ds.total_episodes == 12 and all(ep.terminations[-1] for ep in ds)
    conds = [m["condition"] for m in ecosystem.episode_metadata(ds)]
    assert sorted(set(conds)) == sorted(src.curricula)
    assert ecosystem.check_replay(ds) == 12
    bad = {**src.curricula["baseline"], "demos": [
        {**src.curricula["baseline"]["demos"][0], "reward": 1.0}]}
    with pytest.raises(ValueError, match="curriculum demo 0: replaying its actions gives"):
        ecosystem.curriculum_episodes(dom, bad)


def test_candidate_demonstrations_are_optimal_under_w_star():
    from cfteach import mdp

    dom = domains.load("skateboard")
    eps = ecosystem.candidate_episodes(dom, env_indices=[5])
    batch = mdp.compile_domain(dom)
    V = mdp.value_iteration(batch, np.asarray(dom.weights)[None]).V[5, 0]
    inst = dom.instance(5)
    assert len(eps) == len(inst.states())  # one per reachable non-terminal state
    for ep in eps:
        s = inst.state_from_json(json.loads(ep.options["start_state"]))
        assert ep.total_reward == pytest.approx(V[batch.index_of(5, s)], abs=1e-9)
        assert ep.terminated
    ds = ecosystem.write_dataset(eps, "cfteach/skateboard/candidates-v0", dom)
    assert ecosystem.check_replay(ds) == len(eps)


def test_check_replay_finds_an_episode_that_does_not_replay():
    dom = domains.load("skateboard")
    eps = ecosystem.candidate_episodes(dom, env_indices=[7])[:3]
    eps[1].rewards[-1] += 0.5
    ds = ecosystem.write_dataset(eps, "cfteach/skateboard/broken-v0", dom)
    with pytest.raises(ValueError, match=r"episode 1 step \d+: reward"):
        ecosystem.check_replay(ds)


def test_datasets_go_under_the_given_root_and_are_not_overwritten(tmp_path):
    dom = domains.load("skateboard")
    eps = ecosystem.candidate_episodes(dom, env_indices=[7])[:2]
    root = tmp_path / "elsewhere"
    ecosystem.write_dataset(eps, "cfteach/skateboard/x-v0", dom, root=root)
    assert (root / "cfteach" / "skateboard" / "x-v0" / "data").is_dir()
    assert os.environ["MINARI_DATASETS_PATH"] != str(root)  # restored afterwards
    with pytest.raises(ValueError, match="exists already"):
        ecosystem.write_dataset(eps, "cfteach/skateboard/x-v0", dom, root=root)
    ecosystem.write_dataset(eps[:1], "cfteach/skateboard/x-v0", dom, root=root, force=True)
    assert ecosystem.load_dataset("cfteach/skateboard/x-v0", root).total_episodes == 1
    with pytest.raises(ValueError, match="no local Minari dataset 'cfteach/nope-v0'"):
        minari_io.load_dataset("cfteach/nope-v0", root)


# ----------------------------------------------------------------------------- the CLI
def _run(args):
    result = CliRunner().invoke(app, args)
    return result.exit_code, result.output


def test_cli_writes_and_checks_answer_and_demo_datasets(study, tmp_path):
    study_dir, export = study
    root = tmp_path / "root"
    code, out = _run(["export", "minari", "answers", "--study", str(study_dir),
                      "--export", str(export), "--status", "completed", "--root", str(root)])
    assert code == 0, out
    for name in ("delivery", "tiles", "skateboard"):
        assert f"cfteach/{name}/answers-v0: 18 episodes" in out
    assert out.count("all 18 replay to their rewards") == 3
    code, out = _run(["export", "minari", "check", "cfteach/tiles/answers-v0",
                      "--root", str(root)])
    assert (code, out.strip()) == (0, "cfteach/tiles/answers-v0: all 18 episodes replay "
                                      "to their rewards")
    code, out = _run(["export", "minari", "demos", "skateboard",
                      "--instances", "3", "--root", str(root)])
    assert code == 0 and "cfteach/skateboard/candidates-v0:" in out
    n = len(domains.load("skateboard").instance(3).states())
    assert ecosystem.load_dataset("cfteach/skateboard/candidates-v0", root).total_episodes == n


@pytest.mark.parametrize("args, message", [
    (["demos", "nowhere"], "domain 'nowhere'"),
    (["answers", "--study", "/nonexistent", "--export", "/nonexistent"], "no such file"),
    (["check", "cfteach/none-v0"], "no local Minari dataset"),
])
def test_cli_errors_are_one_line(args, message, tmp_path):
    code, out = _run(["export", "minari", *args, "--root", str(tmp_path)])
    assert code == 2
    assert message in out and "Traceback" not in out
    assert len([line for line in out.splitlines() if line.startswith("Error:")]) == 1


def test_a_reader_recovers_the_environment_without_importing_cfteach(tmp_path):
    import subprocess
    import sys

    dom = domains.load("skateboard")
    ecosystem.write_dataset(ecosystem.candidate_episodes(dom, env_indices=[6])[:4],
                            "cfteach/skateboard/r-v0", dom)
    code = ("import sys, minari\n"
            "ds = minari.load_dataset('cfteach/skateboard/r-v0')\n"
            "print('cfteach' in sys.modules)\n"
            "env = ds.recover_environment()\n"
            "ep = ds[0]\n"
            "meta = next(iter(ds.storage.get_episode_metadata([0])))\n"
            "obs, _ = env.reset(options=meta['options'])\n"
            "print(env.spec.id, (obs == ep.observations[0]).all())\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "cfteach/Skateboard-v0", "True"]


# ------------------------------------------------------- interrupted and repeated exports
def test_an_interrupted_export_leaves_no_dataset(minari_root, monkeypatch):
    dom = domains.load("skateboard")
    eps = ecosystem.candidate_episodes(dom, env_indices=[7])[:2]

    def ctrl_c(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(minari_io, "_attrs", ctrl_c)  # after Minari wrote the episodes
    with pytest.raises(KeyboardInterrupt):
        ecosystem.write_dataset(eps, "cfteach/skateboard/x-v0", dom)
    assert "cfteach/skateboard/x-v0" not in minari.list_local_datasets()
    assert [p.name for p in minari_root.iterdir() if p.name.startswith(".")] == []
    monkeypatch.undo()
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(minari_root))
    ds = ecosystem.write_dataset(eps, "cfteach/skateboard/x-v0", dom)  # no --force needed
    assert ds.total_episodes == 2 and ecosystem.check_replay(ds) == 2


def test_replacing_a_dataset_keeps_the_old_one_until_the_new_one_is_in(minari_root,
                                                                       monkeypatch):
    dom = domains.load("skateboard")
    eps = ecosystem.candidate_episodes(dom, env_indices=[7])[:3]
    ecosystem.write_dataset(eps, "cfteach/skateboard/x-v0", dom)

    def ctrl_c(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(minari_io, "_attrs", ctrl_c)  # after Minari wrote the episodes
    with pytest.raises(KeyboardInterrupt):
        ecosystem.write_dataset(eps[:1], "cfteach/skateboard/x-v0", dom, force=True)
    monkeypatch.undo()
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(minari_root))
    assert ecosystem.load_dataset("cfteach/skateboard/x-v0").total_episodes == 3


def test_check_fails_on_a_dataset_without_episodes(monkeypatch):
    monkeypatch.setattr(ecosystem, "load_dataset", lambda *_a, **_k: object())
    monkeypatch.setattr(ecosystem, "check_replay", lambda *_a, **_k: 0)
    code, out = _run(["export", "minari", "check", "cfteach/empty-v0"])
    assert code == 1
    assert "no episodes" in out and "all 0 episodes replay" not in out


def test_an_existing_dataset_is_refused_before_any_work(minari_root, monkeypatch):
    (minari_root / "cfteach" / "tiles" / "candidates-v0" / "data").mkdir(parents=True)

    def no_work(*_a, **_k):
        raise AssertionError("planned before refusing")

    monkeypatch.setattr(ecosystem, "candidate_episodes", no_work)
    code, out = _run(["export", "minari", "demos", "tiles"])
    assert code == 2
    assert "'cfteach/tiles/candidates-v0' exists already (--force replaces it)" in out


def test_export_shows_progress_only_on_a_terminal_and_not_quiet(monkeypatch):
    from cfteach.cli import _progress

    seen = []

    def fake(dom, env_indices=None, progress=False):
        seen.append(progress)
        raise ValueError("stop here")

    monkeypatch.setattr(ecosystem, "candidate_episodes", fake)
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: True)
    _run(["export", "minari", "demos", "skateboard"])
    _run(["export", "minari", "demos", "skateboard", "--quiet"])
    assert seen == [True, False]
