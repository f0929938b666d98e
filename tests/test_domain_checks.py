"""cfteach.domains.check and cfteach.mdp.soundness: a domain that cannot be taught gives a
named error before planning (unreachable goals, reward loops, w* outside the beliefs, too
few features), and every curriculum's final belief contains w*."""

from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from cfteach import domains
from cfteach.domains import from_dict
from cfteach.domains.check import DomainCheckError, errors_of
from cfteach.mdp.soundness import check_domain
from cfteach.teaching import select_tests, teach
from cfteach.teaching.records import BeliefError

DOCS = Path(__file__).resolve().parents[1] / "docs" / "domains.md"


def corridor(**changes: object) -> dict:
    """The docs/domains.md example as a dict (tests change one thing at a time)."""
    text = DOCS.read_text()
    m = re.search(r"<!-- example-domain -->\s*```toml\n(.*?)```", text, re.S)
    assert m
    return copy.deepcopy(tomllib.loads(m.group(1)))


def test_the_documented_example_and_the_builtins_pass() -> None:
    assert check_domain(from_dict(corridor())) == []
    for name in domains.builtin_names():
        assert errors_of(check_domain(domains.load(name))) == []


def test_unreachable_goal_is_a_named_error_per_instance() -> None:
    data = corridor()
    data["domain"]["walls"] = [[3, 1], [3, 2], [3, 3]]
    dom = from_dict(data, source="walled.toml")
    found = errors_of(check_domain(dom))
    assert [f.code for f in found] == ["unreachable_goal"] * 4
    for f, code in zip(found, ([0, 0], [0, 1], [1, 0], [1, 1]), strict=True):
        assert f"env code {code}" in f.message and "cannot be reached" in f.message
    # teach and tests stop with the same error instead of an empty curriculum
    with pytest.raises(DomainCheckError, match=r"instance 0 .*cannot be reached.*3 more"):
        teach(dom, "proposed")
    with pytest.raises(DomainCheckError, match="cannot be reached"):
        select_tests(dom)


def test_a_reward_loop_that_w_star_pays_for_is_named() -> None:
    data = corridor()
    data["features"][1]["weight"] = 3.0  # carrying the key pays more than a step costs
    dom = from_dict(data)
    found = errors_of(check_domain(dom))
    assert {f.code for f in found} == {"reward_loop"}
    # only the instances with the key (bit 1 set) have the loop
    assert [f.message.split("env code ")[1][:6] for f in found] == ["[0, 1]", "[1, 1]"]
    with pytest.raises(DomainCheckError, match="pays for a loop"):
        teach(dom, "baseline")


def test_w_star_outside_the_posterior_or_prior_is_named() -> None:
    data = corridor()
    data["beliefs"]["posterior"] = [[1, 0, 0], [0, 0, -1]]  # ice weight is -2: violated
    found = errors_of(check_domain(from_dict(data)))
    assert [f.code for f in found] == ["w_star_posterior"]
    assert "row 0 [1, 0, 0]" in found[0].message
    data = corridor()
    data["beliefs"]["prior"] = [[0, 0, 1]]
    assert [f.code for f in errors_of(check_domain(from_dict(data)))] == ["w_star_prior"]


def test_fewer_than_three_features_is_named_before_planning() -> None:
    dom = domains.load("random:5x5:f2:n4:s0")
    found = errors_of(check_domain(dom))
    assert [f.code for f in found] == ["features"]
    with pytest.raises(DomainCheckError, match="at least 3"):
        teach(dom, "proposed")


def test_random_specs_load_everywhere_a_domain_is_named() -> None:
    dom = domains.load("random:5x5:f3:n4:s0")
    assert dom.n_features == 3 and len(dom.instances()) == 4
    assert domains.load("random:5x5:f3:n4:s0") is dom  # cached like the built-ins
    with pytest.raises(ValueError, match="random:WxH:fF:nN:sS"):
        domains.load("random:5x5:f3")
    with pytest.raises(ValueError, match="power of two"):
        domains.load("random:5x5:f3:n3:s0")


def test_misspelt_domain_names_get_a_suggestion(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="did you mean 'delivery'"):
        domains.load("delivry")
    with pytest.raises(ValueError, match="is a directory"):
        domains.load(tmp_path)


def test_a_curriculum_whose_belief_lost_w_star_is_refused(monkeypatch) -> None:
    # Import the users first: importing one while common.tightened is patched would bind
    # (and, on undo, restore) the wrong function.
    from cfteach.teaching import baseline, common, counterfactual

    real = common.tightened

    def wrong(belief, rows):  # a teaching bug: add the flipped constraints
        return real(belief, -np.asarray(rows))

    for module in (common, baseline, counterfactual):
        monkeypatch.setattr(module, "tightened", wrong)
    with pytest.raises(BeliefError, match="does not contain w"):
        teach("skateboard", "baseline")


def test_a_random_domain_loads_by_the_name_its_json_files_carry() -> None:
    dom = domains.load("random:5x5:f3:n4:s0")
    assert domains.load(dom.name) is dom  # "random-5x5-f3-n4-s0"


def test_states_that_cannot_reach_the_goal_are_named() -> None:
    from dataclasses import replace

    from cfteach.mdp import compile_domain, value_iteration
    from cfteach.mdp.soundness import planning_findings

    dom = from_dict(corridor())
    batch = compile_domain(dom)
    vals = value_iteration(batch, np.asarray(dom.weights)[None])
    assert planning_findings(dom, batch, vals) == []
    V = vals.V.copy()
    V[2, 0, [3, 5]] = -np.inf  # as if two states of instance 2 were cut off from the goal
    found = planning_findings(dom, batch, replace(vals, V=V))
    assert [f.code for f in found] == ["dead_end"]
    assert "env code [1, 0]" in found[0].message and "from 2 of" in found[0].message
