"""Simulated learners taught by the closed-loop teacher, and the open-loop control at equal
budget.

Each learner has a teacher of its own (`cfteach.closedloop.ClosedLoopTeacher`): it is shown
the teacher's demonstrations and feedback (learning from feedback as from a demonstration:
the optimal answer from the failed test's start), answers its diagnostic tests as it answers
any test, and the teacher only ever sees those answers. After teaching, every learner takes
the same held-out post-teaching tests as the open-loop conditions.

`equal_budget_demos` builds the control that tells adaptivity apart from mere exposure:
the `proposed` curriculum with as many demonstrations as closed-loop showed demonstrations
and feedback on average, repeated from the start when it runs out (blind repetition).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from cfteach.simulate.domain_refs import domain_label, load_domain

CLOSED_LOOP = "closed_loop"
EQUAL_BUDGET = "proposed_equal_budget"
#: Per learner, `proposed` shown as many items as that learner's closed-loop session.
EQUAL_ITEMS = "proposed_equal_items"
#: The open-loop curriculum every closed-loop session covers (docs/closed-loop.md).
BACKBONE = "proposed"
#: Plays of every post-test behind each closed-loop learner's expected score.
EXPECTED_DRAWS = 64


@cache
def _pool(domain_ref: Any, profile: str, seed: int, held_key: str, human_models: int,
          backbone_key: str = ""):
    """The lesson pool of one (domain, replication), built once per worker process."""
    from cfteach.closedloop import build_pool

    held = [int(x) for x in held_key.split(",") if x]
    backbone = [int(x) for x in backbone_key.split(",") if x]
    return build_pool(load_domain(domain_ref), profile=profile, human_models=human_models,
                      seed=seed, held_out=held, backbone=backbone)


def held_key(domain_ref: Any, profile: str, tests: dict[str, Any]) -> str:
    """The held-out tests as a hashable key of demo indices (for the worker cache)."""
    from cfteach.bec import demo_set
    from cfteach.closedloop import held_out_demos

    ds = demo_set(load_domain(domain_ref), profile)
    return ",".join(str(d) for d in held_out_demos(ds, tests))


def backbone_key(domain_ref: Any, profile: str, curriculum: dict[str, Any] | None) -> str:
    """The backbone curriculum's demonstrations as a hashable key of demo indices, in
    order ("" without one)."""
    if not curriculum:
        return ""
    from cfteach.bec import demo_set
    from cfteach.closedloop.pool import demo_indices

    ds = demo_set(load_domain(domain_ref), profile)
    return ",".join(str(d) for d in demo_indices(ds, curriculum["demos"]))


def run_session(teacher: Any, learners: Any) -> dict[str, int]:
    """Drive one teacher with one simulated learner (`Learners` with n = 1) to the end."""
    pool = teacher.pool
    while (item := teacher.next()) is not None:
        shown = item.to_json(pool)
        if item.kind == "test":  # the teacher sees the moves, as the study's server does
            ans = learners.answer([shown], moves=True)
            teacher.observe({"actions": ans["actions"][0][0]})
        else:
            learners.observe(shown)  # feedback shows the optimal answer: a demonstration
            teacher.observe({})
    return teacher.counts()


def closed_loop_chunk(chunk: dict[str, Any]) -> dict[str, Any]:
    """Teach and test one block of learners, each with its own teacher; runs in a worker."""
    from cfteach.closedloop import ClosedLoopTeacher, TeacherSettings, probes
    from cfteach.simulate.learners import Learners

    dom = load_domain(chunk["domain"])
    pool = _pool(chunk["domain"], chunk["profile"], chunk["material_seed"], chunk["held_key"],
                 chunk["pool_human_models"], chunk.get("backbone_key", ""))
    settings = TeacherSettings(**chunk.get("teacher", {}))
    ss = np.random.SeedSequence(chunk["entropy"])
    keys = ("correct", "reward", "finished", "contains_w_star", "belief_area",
            "belief_area_se", "belief_constraints", "ignored_updates")
    out: dict[str, list] = {k: [] for k in (*keys, "items", "demos", "tests", "feedback",
                                            "predicted", "knowledge", "probe_observed",
                                            "expected")}
    probe_tests = probes.probe_tests(pool, settings.n_probes, settings.probes)
    for child in ss.spawn(chunk["n"]):
        learner_rng, teacher_seed = np.random.default_rng(child), child.generate_state(1)[0]
        learners = Learners(dom, chunk["model"], 1, rng=learner_rng)
        teacher = ClosedLoopTeacher(pool, settings, seed=int(teacher_seed))
        counts = run_session(teacher, learners)
        pred = teacher.prediction()  # on the teacher's own probes, at its stop
        ans = learners.answer(chunk["tests"]) if chunk["tests"] else None
        # then the teacher's own probes (after the post-tests: their answers are unchanged),
        # to tell a miscalibrated model apart from probes unlike the post-tests
        on_probes = (float(learners.answer(probe_tests)["correct"][0].mean())
                     if probe_tests else np.nan)
        # last, the learner's expected score on the post-tests (its observed one samples
        # it): the ceiling of any per-learner prediction, see `calibration_table`
        expected = (float(learners.expected_correct(chunk["tests"], EXPECTED_DRAWS)[0])
                    if chunk["tests"] else np.nan)
        areas, se = learners.belief_area_estimates()
        for k, v in (("correct", None if ans is None else ans["correct"][0]),
                     ("reward", None if ans is None else ans["reward"][0]),
                     ("finished", None if ans is None else ans["finished"][0]),
                     ("contains_w_star", learners.contains(dom.weights)[0]),
                     ("belief_area", areas[0]), ("belief_area_se", se[0]),
                     ("belief_constraints", len(learners.beliefs[0])),
                     ("ignored_updates", learners.ignored[0]),
                     ("items", sum(counts.values())), ("demos", counts["demonstration"]),
                     ("tests", counts["test"]), ("feedback", counts["feedback"]),
                     ("predicted", np.nan if pred["predicted"] is None else pred["predicted"]),
                     ("knowledge", np.nan if pred["knowledge"] is None else pred["knowledge"]),
                     ("probe_observed", on_probes), ("expected", expected)):
            out[k].append(v)
    res: dict[str, Any] = {k: np.asarray(v) for k, v in out.items()}
    res["optimal_reward"] = None if ans is None else ans["optimal_reward"]
    if not chunk["tests"]:
        res.update(correct=None, reward=None, finished=None)
    return res


def equal_budget_demos(curriculum: dict[str, Any], budget: int) -> list[dict[str, Any]]:
    """The curriculum's demonstrations, repeated from the start until `budget` are shown."""
    demos = list(curriculum["demos"])
    if budget < 1 or not demos:
        return []
    return [demos[k % len(demos)] for k in range(budget)]


def equal_budget_override(material: list[Any], result: Any, *, profile: str,
                          human_models: int, known: str | None = None
                          ) -> dict[tuple[str, int, str, str], list]:
    """The `proposed_equal_budget` demonstrations per (domain, seed, learner model): the
    `proposed` curriculum capped at closed-loop's mean demonstrations + feedback for that
    learner model, repeated from the start when it stops early (blind repetition)."""
    from cfteach import teaching

    b = result.beliefs[result.beliefs["condition"] == CLOSED_LOOP]
    shown = (b["demos"] + b["feedback"]).groupby(
        [b["domain"], b["seed"], b["learner_model"]], observed=True).mean()
    taught: dict[tuple[str, int, int], dict[str, Any]] = {}
    out: dict[tuple[str, int, str, str], list] = {}
    for (label, mseed, model), mean in shown.items():
        mat = next(m for m in material if domain_label(m.domain) == label and m.seed == mseed)
        cap = max(1, int(round(float(mean))))
        if (label, mseed, cap) not in taught:
            taught[(label, mseed, cap)] = teaching.teach(
                load_domain(mat.domain), "proposed", profile=profile, seed=mseed,
                human_models=human_models, max_demos=cap, known=known).to_json()
        out[(label, int(mseed), EQUAL_BUDGET, str(model))] = equal_budget_demos(
            taught[(label, mseed, cap)], cap)
    return out


def equal_items_override(material: list[Any], result: Any, *, profile: str,
                         human_models: int, known: str | None = None
                         ) -> dict[tuple[str, int, str, str], dict]:
    """The `proposed_equal_items` demonstrations per (domain, seed, learner model) and
    learner: the `proposed` curriculum (taught up to the longest closed-loop session)
    cut to, or repeated from the start up to, the number of items that learner's own
    closed-loop session showed, tests and feedback included."""
    from cfteach import teaching

    b = result.beliefs[result.beliefs["condition"] == CLOSED_LOOP]
    out: dict[tuple[str, int, str, str], dict] = {}
    for (label, mseed, model), g in b.groupby(["domain", "seed", "learner_model"],
                                               observed=True):
        mat = next(m for m in material if domain_label(m.domain) == label and m.seed == mseed)
        cap = max(1, int(g["items"].max()))
        taught = teaching.teach(load_domain(mat.domain), "proposed", profile=profile,
                                seed=int(mseed), human_models=human_models,
                                max_demos=cap, known=known).to_json()
        out[(str(label), int(mseed), EQUAL_ITEMS, str(model))] = {
            int(i): equal_budget_demos(taught, max(1, int(n)))
            for i, n in zip(g["learner"], g["items"], strict=True)}
    return out
