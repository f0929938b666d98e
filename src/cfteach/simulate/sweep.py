"""Sweeps: teach every condition's curriculum to many simulated learners, test them, and
summarise — the study in minutes, before running it with people.

Work is cut into coarse chunks run through `cfteach.parallel` (local processes, Dask or
Ray): one chunk per (domain, seed) for teaching + test selection, one per block of learners
for the simulation. Every simulation chunk draws from a `numpy.random.SeedSequence` built
from its *identity* (root seed, replication seed, domain, condition, learner model, block),
so results do not depend on the backend, the number of workers, or which other domains and
conditions are in the same sweep.
"""

from __future__ import annotations

import json
import time
import zlib
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cfteach.jsonable import to_jsonable
from cfteach.simulate.closed_loop import (
    BACKBONE,
    CLOSED_LOOP,
    EQUAL_BUDGET,
    EQUAL_ITEMS,
    backbone_key,
    closed_loop_chunk,
    equal_budget_override,
    equal_items_override,
    held_key,
)
from cfteach.simulate.compare import calibration_table, ratio_table
from cfteach.simulate.domain_refs import domain_label, load_domain, parse_domain
from cfteach.simulate.learners import LearnerModel, Learners, learner_model
from cfteach.simulate.summary import (
    h1_correlations,
    interaction_plot,
    items_table,
    ordering,
    proportion_table,
    regret_table,
)

CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")
#: Conditions `run_sweep` takes: the paper's four, closed-loop teaching and no teaching.
SWEEP_CONDITIONS = (*CONDITIONS, CLOSED_LOOP)
NO_TEACHING = "none"  # control: learners who see no demonstration at all
CLUSTER_LEVEL = {0: "high", 2: "medium", 4: "low"}  # tests.json cluster -> difficulty (Alg. 2)
SCHEMA = "cfteach.simulation/1"


# -- teaching material ---------------------------------------------------------------------
@dataclass
class Material:
    """What one (domain, seed) replication teaches and tests with."""

    domain: str | tuple
    seed: int
    curricula: dict[str, dict[str, Any]]   # condition -> cfteach.curriculum/1
    tests: dict[str, Any]                  # cfteach.tests/1
    seconds: float = 0.0


def _teach_chunk(chunk: dict[str, Any]) -> Material:
    """Teaching + test selection for one (domain, seed); runs in a worker."""
    from cfteach import teaching

    t0 = time.perf_counter()
    dom = load_domain(chunk["domain"])
    curricula = {}
    objects = []
    for cond in chunk["conditions"]:
        cur = teaching.teach(dom, cond, profile=chunk["profile"], seed=chunk["seed"],
                             human_models=chunk["human_models"], known=chunk.get("known"))
        objects.append(cur)
        curricula[cond] = cur.to_json()
    tests = teaching.select_tests(dom, training=tuple(objects), profile=chunk["profile"],
                                  seed=chunk["seed"], per_level=chunk["per_level"],
                                  human_models=chunk["human_models"],
                                  include_candidates=chunk["include_candidates"],
                                  known=chunk.get("known"))
    return Material(chunk["domain"], chunk["seed"], curricula, tests.to_json(),
                    time.perf_counter() - t0)


def teach_material(domains: list[str | tuple], conditions: list[str], seeds: list[int], *,
                   profile: str = "default", human_models: int = 8, per_level: int = 6,
                   include_candidates: bool = False, executor=None,
                   progress: bool = False, known: str | None = None) -> list[Material]:
    """Run `cfteach.teaching` for every (domain, seed) in parallel chunks."""
    from cfteach.parallel import map_chunks

    taught = [c for c in conditions if c not in (NO_TEACHING, CLOSED_LOOP)]
    if CLOSED_LOOP in conditions and BACKBONE not in taught:  # the closed loop's backbone
        taught.append(BACKBONE)
    chunks = [{"domain": d, "seed": s, "conditions": taught, "profile": profile,
               "human_models": human_models, "per_level": per_level,
               "include_candidates": include_candidates, "known": known}
              for d in domains for s in seeds]
    return map_chunks(_teach_chunk, chunks, progress=progress, desc="teaching",
                      executor=executor)


def load_material(source: str | Path, domains: list[str | tuple], conditions: list[str],
                  seed: int = 0) -> list[Material]:
    """Read curricula and tests written by `cfteach reproduce --out DIR`
    (`DIR/<domain>/<condition>.json`, `DIR/<domain>/tests.json`)."""
    source = Path(source)
    out = []
    for d in domains:
        folder = source / domain_label(d)
        curricula = {}
        for cond in conditions:
            if cond == NO_TEACHING:
                continue
            path = folder / f"{cond}.json"
            if not path.exists():
                raise FileNotFoundError(f"no curriculum for condition {cond!r} at {path}")
            curricula[cond] = _read_json(path, "cfteach.curriculum/1")
        out.append(Material(d, seed, curricula, _read_json(folder / "tests.json",
                                                             "cfteach.tests/1")))
    return out


def _read_json(path: Path, schema: str) -> dict[str, Any]:
    if not path.exists():
        raise FileNotFoundError(f"missing file {path}")
    data = json.loads(path.read_text())
    if data.get("schema") != schema:
        raise ValueError(f"{path}: expected schema {schema!r}, found {data.get('schema')!r}")
    return data


def answer_items(tests: dict[str, Any], include_candidates: bool = False) -> list[dict[str, Any]]:
    """The tests a learner answers: the selected tests per level, and optionally every
    candidate (labelled by its k-means cluster: 0 high, 2 medium, 4 low, others none)."""
    items = []
    for level in ("low", "medium", "high"):
        for k, t in enumerate(tests.get("tests", {}).get(level, [])):
            items.append({**_test_core(t), "test": f"{level}-{k}", "source": "selected",
                          "difficulty": level, "overlap": float(t.get("overlap", np.nan)),
                          "optimal_reward": t.get("optimal_reward")})
    if include_candidates:
        if "candidates" not in tests:
            raise ValueError("the test set has no 'candidates' (select tests with "
                             "include_candidates=True / `--all`)")
        for k, c in enumerate(tests["candidates"]):
            items.append({**_test_core(c), "test": f"candidate-{k}", "source": "candidates",
                          "difficulty": CLUSTER_LEVEL.get(c.get("cluster"), "other"),
                          "overlap": float(c.get("overlap", np.nan)),
                          "optimal_reward": c.get("optimal_reward")})
    return items


def _test_core(t: dict[str, Any]) -> dict[str, Any]:
    core: dict[str, Any] = {k: t[k] for k in ("env_index", "env_code", "start_state") if k in t}
    if "start_state" not in core:
        raise ValueError("a test lacks 'start_state'")
    return core


# -- simulation ----------------------------------------------------------------------------
def _entropy(*parts: int | str) -> list[int]:
    return [p if isinstance(p, int) else zlib.crc32(p.encode()) for p in parts]


def _simulate_chunk(chunk: dict[str, Any]) -> dict[str, Any]:
    """Teach and test one block of learners; runs in a worker."""
    if chunk.get("closed_loop"):
        return closed_loop_chunk(chunk)
    ss = np.random.SeedSequence(chunk["entropy"])
    dom = load_domain(chunk["domain"])
    learners = Learners(dom, chunk["model"], chunk["n"], rng=np.random.default_rng(ss))
    learners.teach(chunk["demos"])
    ans = learners.answer(chunk["tests"]) if chunk["tests"] else None
    areas, area_se = learners.belief_area_estimates()
    return {
        "correct": None if ans is None else ans["correct"],
        "reward": None if ans is None else ans["reward"],
        "finished": None if ans is None else ans["finished"],
        "optimal_reward": None if ans is None else ans["optimal_reward"],
        "contains_w_star": learners.contains(dom.weights),
        "belief_area": areas,
        "belief_area_se": area_se,
        "belief_constraints": np.array([len(b) for b in learners.beliefs]),
        "ignored_updates": learners.ignored,
        "items": np.full(chunk["n"], len(chunk["demos"])),
        "demos": np.full(chunk["n"], len(chunk["demos"])),
        "tests": np.zeros(chunk["n"], dtype=np.int64),
        "feedback": np.zeros(chunk["n"], dtype=np.int64),
        "predicted": np.full(chunk["n"], np.nan),
        "knowledge": np.full(chunk["n"], np.nan),
        "probe_observed": np.full(chunk["n"], np.nan),
        "expected": np.full(chunk["n"], np.nan),
    }


@dataclass
class SweepResult:
    """Everything a sweep produced; `write(out_dir)` saves JSON, CSV and figures."""

    answers: pd.DataFrame
    beliefs: pd.DataFrame
    settings: dict[str, Any]
    timing: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        sel = self.answers[self.answers["source"] == "selected"]
        cand = self.answers[self.answers["source"] == "candidates"]
        table = proportion_table(sel) if len(sel) else []
        out: dict[str, Any] = {
            "schema": SCHEMA,
            "settings": self.settings,
            "proportion_optimal": table,
            "ordering": ordering(table),
            "h1": [dict(r, source="selected") for r in h1_correlations(sel)] if len(sel)
            else [],
            "regret": regret_table(sel) if len(sel) else {},
            "items_shown": items_table(self.beliefs),
            "ratios": ratio_table(sel, seed=int(self.settings.get("seed", 0))) if len(sel)
            else {},
            "calibration": calibration_table(sel, self.beliefs) if len(sel) else {},
            "beliefs": _belief_summary(self.beliefs),
            "timing_seconds": self.timing,
        }
        if len(cand):
            ctable = proportion_table(cand)
            out["proportion_optimal_candidates"] = ctable
            out["ordering_candidates"] = ordering(ctable)
            out["h1"] += [dict(r, source="candidates") for r in h1_correlations(cand)]
        return out

    def merged(self, other: SweepResult) -> SweepResult:
        """This sweep's rows and another's (e.g. a control run after it), one result."""
        settings = dict(self.settings)
        settings["conditions"] = [*self.settings["conditions"],
                                  *[c for c in other.settings["conditions"]
                                    if c not in self.settings["conditions"]]]
        timing = dict(self.timing)
        timing["simulation"] = timing.get("simulation", 0.0) + other.timing.get("simulation", 0)
        return SweepResult(pd.concat([self.answers, other.answers], ignore_index=True),
                           pd.concat([self.beliefs, other.beliefs], ignore_index=True),
                           settings, timing)

    def write(self, out_dir: str | Path) -> dict[str, Any]:
        """Write `results.json`, `answers.csv` (selected tests), `candidates.csv`
        (per-candidate proportions), `beliefs.csv` and `proportion_optimal_<domain>.png/svg`."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        summ = self.summary()
        (out / "results.json").write_text(json.dumps(to_jsonable(summ), indent=2) + "\n")
        sel = self.answers[self.answers["source"] == "selected"]
        sel.to_csv(out / "answers.csv", index=False)
        cand = self.answers[self.answers["source"] == "candidates"]
        if len(cand):
            (cand.groupby(["learner_model", "domain", "condition", "seed", "test",
                           "difficulty", "overlap"], observed=True)["correct"]
             .agg(["mean", "size"]).rename(columns={"mean": "proportion_optimal",
                                                    "size": "n_answers"})
             .reset_index().to_csv(out / "candidates.csv", index=False))
        self.beliefs.to_csv(out / "beliefs.csv", index=False)
        figures = []
        table = summ["proportion_optimal"]
        for dom in sorted({r["domain"] for r in table}):
            figures += [str(p.name) for p in interaction_plot(
                table, out / f"proportion_optimal_{dom}", domain=dom,
                title=f"Simulated learners — {dom}")]
        summ["figures"] = figures
        (out / "results.json").write_text(json.dumps(to_jsonable(summ), indent=2) + "\n")
        return summ


def _belief_summary(beliefs: pd.DataFrame) -> list[dict[str, Any]]:
    rows = []
    for (model, dom, cond), g in beliefs.groupby(["learner_model", "domain", "condition"],
                                                 observed=True):
        area = g["belief_area"].to_numpy(float)
        se = g["belief_area_se"].to_numpy(float)
        rows.append({"learner_model": model, "domain": dom, "condition": cond,
                     "n_learners": int(len(g)),
                     "contains_w_star": float(g["contains_w_star"].mean()),
                     "mean_belief_area": float(np.nanmean(area)) if np.isfinite(area).any()
                     else None,
                     # standard error of that mean from the per-learner estimates (0: exact)
                     "mean_belief_area_se": float(np.sqrt(np.nansum(se ** 2)) / len(se)),
                     "mean_constraints": float(g["belief_constraints"].mean()),
                     "ignored_updates": int(g["ignored_updates"].sum())})
    return rows


def simulate(material: list[Material], learner_models: Sequence[str | LearnerModel], *,
             n_learners: int = 32, conditions: list[str] | None = None,
             include_candidates: bool = False, seed: int = 0, chunk_learners: int = 16,
             executor=None, progress: bool = False, profile: str = "default",
             human_models: int = 8, teacher: dict[str, Any] | None = None,
             demos_override: dict[tuple[str, int, str, str], list] | None = None
             ) -> SweepResult:
    """Teach each condition's curriculum to `n_learners` learners of each model, give them
    the tests (and optionally every candidate), and collect their scored answers.

    ``closed_loop`` gives every learner a closed-loop teacher of its own (settings
    `teacher`, `cfteach.closedloop.TeacherSettings`), with the material's selected tests
    held out. `demos_override[(domain label, material seed, condition, learner model)]`
    replaces a condition's demonstrations for one learner model (the equal-budget control),
    or, as ``{learner id: demonstrations}``, for each learner (the equal-items control).
    """
    from cfteach.parallel import chunk_slices, map_chunks

    if n_learners < 1:
        raise ValueError(f"n_learners must be at least 1, got {n_learners}")
    models = [learner_model(m) for m in learner_models]
    chunks, meta = [], []
    for mat in material:
        label = domain_label(mat.domain)
        conds = conditions or [*mat.curricula]
        items = answer_items(mat.tests, include_candidates)
        public = [{k: v for k, v in it.items() if k in ("env_index", "env_code", "start_state",
                                                         "optimal_reward")} for it in items]
        for cond in conds:
            extra: dict[str, Any] = {}
            demos: list[Any]
            if cond == NO_TEACHING:
                demos = []
            elif cond == CLOSED_LOOP:
                demos = []
                extra = {"closed_loop": True, "profile": profile, "material_seed": mat.seed,
                         "held_key": held_key(mat.domain, profile, mat.tests),
                         "backbone_key": backbone_key(mat.domain, profile,
                                                      mat.curricula.get(BACKBONE)),
                         "pool_human_models": 4 * human_models, "teacher": teacher or {}}
            elif cond in mat.curricula or demos_override:
                demos = mat.curricula.get(cond, {}).get("demos", [])
            else:
                raise ValueError(f"no curriculum for condition {cond!r} in domain {label}")
            for model in models:
                key = (label, mat.seed, cond, model.name)
                shown = demos
                if demos_override is not None and key in demos_override:
                    shown = demos_override[key]
                elif cond not in mat.curricula and cond not in (NO_TEACHING, CLOSED_LOOP):
                    raise ValueError(f"no curriculum for condition {cond!r} in domain {label}")
                # per-learner demonstrations (proposed_equal_items): one group per length
                groups = ([(np.arange(n_learners), shown, ())] if not isinstance(shown, dict)
                          else [(np.array(sorted(i for i in shown if len(shown[i]) == k)),
                                 next(v for v in shown.values() if len(v) == k), (k,))
                                for k in sorted({len(v) for v in shown.values()})])
                for ids, group_demos, tag in groups:
                    for b, sl in enumerate(chunk_slices(len(ids), chunk_size=chunk_learners)):
                        chunks.append({"domain": mat.domain, "model": model,
                                       "n": sl.stop - sl.start, "demos": group_demos,
                                       "tests": public,
                                       "entropy": _entropy(seed, mat.seed, label, cond,
                                                           model.name, b, *tag), **extra})
                        meta.append((label, mat.seed, cond, model.name, ids[sl], items))
    t0 = time.perf_counter()
    results = map_chunks(_simulate_chunk, chunks, progress=progress, desc="simulating",
                         executor=executor)
    elapsed = time.perf_counter() - t0
    frames, belief_rows = [], []
    for (label, mseed, cond, model_name, ids, items), res in zip(meta, results, strict=True):
        belief_rows.append(pd.DataFrame({
            "learner_model": model_name, "domain": label, "condition": cond, "seed": mseed,
            "learner": ids, "contains_w_star": res["contains_w_star"],
            "belief_area": res["belief_area"], "belief_area_se": res["belief_area_se"],
            "belief_constraints": res["belief_constraints"],
            "ignored_updates": res["ignored_updates"], "items": res["items"],
            "demos": res["demos"], "tests": res["tests"], "feedback": res["feedback"],
            "predicted": res["predicted"], "knowledge": res["knowledge"],
            "probe_observed": res["probe_observed"], "expected": res["expected"]}))
        if res["correct"] is None:
            continue
        n, t = res["correct"].shape
        frames.append(pd.DataFrame({
            "domain": label, "condition": cond, "learner_model": model_name, "seed": mseed,
            "learner": np.repeat(ids, t),
            "test": np.tile([it["test"] for it in items], n),
            "source": np.tile([it["source"] for it in items], n),
            "difficulty": np.tile([it["difficulty"] for it in items], n),
            "overlap": np.tile([it["overlap"] for it in items], n),
            "correct": res["correct"].ravel(), "reward": res["reward"].ravel(),
            "finished": res["finished"].ravel(),
            "optimal_reward": np.tile(res["optimal_reward"], n)}))
    answers = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
        columns=["domain", "condition", "learner_model", "seed", "learner", "test", "source",
                 "difficulty", "overlap", "correct", "reward", "finished", "optimal_reward"])
    settings = {"n_learners": n_learners, "seed": seed, "chunk_learners": chunk_learners,
                "include_candidates": include_candidates,
                "domains": sorted({domain_label(m.domain) for m in material}),
                "replication_seeds": sorted({m.seed for m in material}),
                "conditions": conditions or sorted({c for m in material for c in m.curricula}),
                "learner_models": {m.name: asdict(m) for m in models}}
    return SweepResult(answers, pd.concat(belief_rows, ignore_index=True), settings,
                       {"simulation": elapsed})


def check_teacher(teacher: dict[str, Any]) -> None:
    """Closed-loop settings are checked before any work (ValueError naming the field)."""
    import dataclasses

    from cfteach.closedloop import TeacherSettings

    known = {f.name for f in dataclasses.fields(TeacherSettings)}
    bad = sorted(set(teacher) - known)
    if bad:
        raise ValueError(f"unknown closed-loop setting(s) {bad}; known: {', '.join(sorted(known))}")
    TeacherSettings(**teacher)


def run_sweep(domains: list[str], conditions: list[str] | None = None,
              learner_models: list[str] | None = None, *, n_learners: int = 32,
              seeds: int = 1, include_candidates: bool = False, source: str | Path | None = None,
              profile: str = "default", human_models: int = 8, per_level: int = 6,
              seed: int = 0, backend: str = "local", n_workers: int | None = None,
              scheduler: str | None = None, chunk_learners: int = 16,
              progress: bool = False, teacher: dict[str, Any] | None = None,
              known: str | None = None) -> SweepResult:
    """The whole sweep behind `cfteach simulate`: teach (or read `source`), then simulate.

    `known`: features whose weight the learners are told (`teaching.teach`; None: each
    domain file's ``[beliefs] known``).
    `teacher`: `cfteach.closedloop.TeacherSettings` fields for ``closed_loop``."""
    from cfteach.parallel import Executor

    conditions = list(conditions or [*CONDITIONS, NO_TEACHING])
    bad = [c for c in conditions if c not in (*SWEEP_CONDITIONS, NO_TEACHING)]
    if bad:
        raise ValueError(f"unknown condition(s) {bad}; choose from "
                         f"{', '.join((*SWEEP_CONDITIONS, NO_TEACHING))}")
    if seeds < 1:
        raise ValueError(f"seeds must be at least 1, got {seeds}")
    if source is not None and seeds > 1:
        raise ValueError("seeds > 1 replicates teaching and test selection, but with a source "
                         "folder the curricula are fixed; vary the learners with seed instead")
    refs = [parse_domain(d) for d in domains]
    models = learner_models or ["counterfactual", "noisy"]
    if teacher:
        check_teacher(teacher)  # before any work
    with Executor(backend=backend, n_workers=n_workers, scheduler=scheduler) as ex:
        t0 = time.perf_counter()
        if source is not None:
            material = load_material(source, refs, conditions)
        else:
            material = teach_material(refs, conditions, list(range(seeds)), profile=profile,
                                      human_models=human_models, per_level=per_level,
                                      include_candidates=include_candidates, executor=ex,
                                      progress=progress, known=known)
        t_teach = time.perf_counter() - t0
        common: dict[str, Any] = {
            "n_learners": n_learners, "include_candidates": include_candidates, "seed": seed,
            "chunk_learners": chunk_learners, "executor": ex, "progress": progress,
            "profile": profile, "human_models": human_models, "teacher": teacher}
        result = simulate(material, models, conditions=conditions, **common)
        if CLOSED_LOOP in conditions:
            t1 = time.perf_counter()
            override: dict[tuple[str, int, str, str], Any] = equal_budget_override(
                material, result, profile=profile, human_models=human_models, known=known)
            override.update(equal_items_override(material, result, profile=profile,
                                                 human_models=human_models, known=known))
            control = simulate(material, models, conditions=[EQUAL_BUDGET, EQUAL_ITEMS],
                               demos_override=override, **common)
            result = result.merged(control)
            result.timing["equal_budget"] = time.perf_counter() - t1
    result.timing["teaching"] = t_teach
    result.settings.update(backend=backend, n_workers=n_workers, profile=profile,
                           source=None if source is None else str(source))
    return result
