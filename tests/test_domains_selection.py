"""Working on a subset of a domain's environments (`cfteach.domains.subset`, `--envs`):
the syntax, its one-line errors, teaching on all environments = teaching on the domain, and
curricula / tests made on a subset name the original env indices and codes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cfteach import domains
from cfteach.bec import one_action_constraints
from cfteach.cli import app
from cfteach.domains import load, parse_envs, subset
from cfteach.teaching import select_tests, teach
from cli_runner import WideRunner

DELIVERY = load("delivery")  # 64 environments, 6 bits


@pytest.mark.parametrize("text, expected", [
    ("5", [5]),
    ("0,5,7", [0, 5, 7]),
    ("7, 0 ,5", [0, 5, 7]),
    ("000101", [5]),
    ("0::16", [0, 16, 32, 48]),
    (":3", [0, 1, 2]),
    ("60:", [60, 61, 62, 63]),
    ("1:10:4,000000", [0, 1, 5, 9]),
    ("::1", list(range(64))),
])
def test_envs_syntax(text: str, expected: list[int]) -> None:
    assert parse_envs(text, DELIVERY) == expected


@pytest.mark.parametrize("text, message", [
    ("64", "environment index 64 is out of range 0..63"),
    ("0101", "'0101' has 4 bits but env codes have 6"),
    ("0110101", "'0110101' has 7 bits but env codes have 6"),
    ("5,000101", "environment 5 is given twice (as '5' and '000101')"),
    ("3:3", "slice '3:3' selects no environment"),
    ("0::0", "slice '0::0': the step must be at least 1"),
    ("0:70", "slice '0:70': 70 is past the last environment 63"),
    ("", "the selection is empty"),
    ("1,,2", "'1,,2' has an empty item"),
    ("x1", "'x1' is neither an index in 0..63 nor an env code of 6 bits"),
])
def test_bad_selections_are_named(text: str, message: str) -> None:
    with pytest.raises(domains.selection.EnvSelectionError) as err:
        parse_envs(text, DELIVERY)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_subset_keeps_original_indices_and_codes() -> None:
    sub = subset(DELIVERY, "0::16")
    assert [i.index for i in sub.instances()] == [0, 16, 32, 48]
    assert [i.env_code for i in sub.instances()] == [DELIVERY.instance(i).env_code
                                                      for i in (0, 16, 32, 48)]
    assert sub.instance(5) is DELIVERY.instance(5)  # the family is still the same
    assert sub.n_demonstrations() == sum(len(DELIVERY.instance(i).states())
                                         for i in (0, 16, 32, 48))
    assert subset(sub, [16, 48]).env_indices == (16, 48)
    assert subset(sub, "0::16") is sub
    with pytest.raises(ValueError, match="environment 1 is not in the subset"):
        subset(sub, [1])
    with pytest.raises(ValueError, match="names no environment"):
        subset(DELIVERY, [])


def _without_envs(data: dict) -> dict:
    return {**data, "settings": {k: v for k, v in data["settings"].items() if k != "envs"}}


@pytest.mark.parametrize("condition", ["proposed", "baseline"])
def test_teaching_on_every_env_equals_teaching_on_the_domain(condition: str) -> None:
    dom = load("skateboard")
    full = teach(dom, condition, profile="reference").to_json()
    every = teach(dom, condition, profile="reference", envs="::1").to_json()
    assert every["settings"]["envs"] == list(range(8))
    assert _without_envs(every) == full
    tests_full = select_tests(dom, training=[full], per_level=2).to_json()
    tests_every = select_tests(dom, training=[full], per_level=2,
                               envs=list(range(8))).to_json()
    assert _without_envs(tests_every) == tests_full


def test_a_subset_run_names_original_env_codes() -> None:
    chosen = [3, 21, 42, 60]
    codes = ",".join("".join(map(str, DELIVERY.instance(i).env_code)) for i in chosen)
    cur = teach(DELIVERY, "proposed", envs=codes).to_json()
    assert cur["settings"]["envs"] == chosen
    assert cur["demos"]
    for d in cur["demos"]:
        assert d["env_index"] in chosen
        inst = DELIVERY.instance(d["env_index"])
        assert d["env_code"] == list(inst.env_code)
        inst.state_from_json(d["start_state"])
        # the demonstration's one-step constraints, asked of the full domain by that index
        assert one_action_constraints(DELIVERY, d["env_index"], d["start_state"]).shape[1] == 3
    ts = select_tests(DELIVERY, training=[cur], per_level=1, envs=chosen,
                      include_candidates=True).to_json()
    assert {t["env_index"] for level in ts["tests"].values() for t in level} <= set(chosen)
    assert {c["env_index"] for c in ts["candidates"]} == set(chosen)
    shown = {(d["env_index"], json.dumps(d["start_state"], sort_keys=True))
             for d in cur["demos"]}
    excluded = {(e, json.dumps(s, sort_keys=True)) for e, s in ts["excluded"]}
    assert shown == excluded  # training demonstrations matched by their original index
    assert not shown & {(c["env_index"], json.dumps(c["start_state"], sort_keys=True))
                        for c in ts["candidates"]}


def test_bec_on_a_subset_takes_original_indices() -> None:
    sub = subset(DELIVERY, "0::16")
    start = DELIVERY.instance(16).initial_state
    assert (one_action_constraints(sub, 16, start)
            == one_action_constraints(DELIVERY, 16, start)).all()
    with pytest.raises(ValueError, match=r"environments \(0, 16, 32, 48\), got 5"):
        one_action_constraints(sub, 5, start)


def _cli(*args: str) -> tuple[int, str]:
    r = WideRunner().invoke(app, list(args))
    return r.exit_code, r.output


def test_cli_teach_and_tests_with_envs(tmp_path: Path) -> None:
    out = tmp_path / "cur.json"
    code, text = _cli("teach", "skateboard", "--envs", "1,011,5", "--out", str(out))
    assert code == 0, text
    cur = json.loads(out.read_text())
    assert cur["settings"]["envs"] == [1, 3, 5]
    assert {d["env_index"] for d in cur["demos"]} <= {1, 3, 5}
    tests = tmp_path / "tests.json"
    code, text = _cli("tests", "skateboard", "--envs", "1:6:2", "--training", str(out),
                      "--per-level", "1", "--out", str(tests))
    assert code == 0, text
    ts = json.loads(tests.read_text())
    assert ts["settings"]["envs"] == [1, 3, 5]
    assert {t["env_index"] for lv in ts["tests"].values() for t in lv} <= {1, 3, 5}


@pytest.mark.parametrize("cmd", ["teach", "tests"])
@pytest.mark.parametrize("envs, message", [
    ("8", "environment index 8 is out of range 0..7"),
    ("0101", "'0101' has 4 bits but env codes have 3"),
    ("1,001", "environment 1 is given twice"),
    ("4:4", "selects no environment"),
])
def test_cli_envs_errors_are_one_line(cmd: str, envs: str, message: str,
                                      tmp_path: Path) -> None:
    out = tmp_path / "x.json"
    code, text = _cli(cmd, "skateboard", "--envs", envs, "--out", str(out))
    assert code == 2
    (line,) = text.strip().splitlines()
    assert line.startswith("Error: --envs: ") and message in line
    assert not out.exists()


def test_export_minari_demos_with_envs(tmp_path: Path) -> None:
    from cfteach import ecosystem

    root = tmp_path / "root"
    code, text = _cli("export", "minari", "demos", "skateboard", "--envs", "3,110",
                      "--root", str(root))
    assert code == 0, text
    ds = ecosystem.load_dataset("cfteach/skateboard/candidates-v0", root)
    sk = load("skateboard")
    assert ds.total_episodes == sum(len(sk.instance(i).states()) for i in (3, 6))
    episodes = ecosystem.candidate_episodes(subset(sk, "3,110"))
    assert {ep.env_code for ep in episodes} == {"011", "110"}
    assert {ep.metadata["env_index"] for ep in episodes} == {3, 6}
    code, text = _cli("export", "minari", "demos", "skateboard", "--envs", "9",
                      "--root", str(root))
    assert code == 2 and text.strip() == ("Error: --envs: skateboard: environment index 9 is "
                                          "out of range 0..7")


def test_size_estimate_counts_the_chosen_environments_only() -> None:
    """`--envs` is checked before any work, and the size estimate then covers the chosen
    environments: their count, and their demonstrations summed state by state."""
    from cfteach.domains.size import estimate_size

    sub = subset(DELIVERY, "3,21,42,60")
    est = estimate_size(sub)
    assert est.instances == 4 and est.exact
    assert est.demonstrations == sum(len(DELIVERY.instance(i).states()) for i in (3, 21, 42, 60))
