"""Curricula for the study's four conditions and test selection (the paper's Section IV,
Algorithms 1 and 2; docs/teaching.md).

    from cfteach.teaching import teach, select_tests
    cur = teach("delivery", "proposed", profile="reference")
    tests = select_tests("delivery", training=[cur], per_level=6)
    cur.to_json(); tests.to_json()

Conditions: ``baseline`` (one-action BEC scaffolding with SCOT and k-means), ``feature_only``
(+ feature scaffolding), ``counterfactual_only`` (Algorithm 1), ``proposed`` (Algorithm 1 +
feature scaffolding). Profiles: ``reference`` reproduces the authors' deterministic choices,
``default`` is what we believe is right; docs/profiles.md lists the differences.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Sequence
from typing import Any

from cfteach.bec import DEFAULT_UNBOUNDED, check_unbounded, resolve_domain
from cfteach.bec.demos import PROFILES, check_profile, demo_set
from cfteach.bec.ties import require_untied
from cfteach.domains import Domain
from cfteach.parallel import Executor
from cfteach.teaching.common import (
    CONDITIONS,
    check_condition,
    check_proportion,
    default_proportion,
)
from cfteach.teaching.distribute import one_step_cache, open_executor, parallel_config
from cfteach.teaching.known import known_names, make_slice, settings_entry
from cfteach.teaching.records import CURRICULUM_SCHEMA, TESTS_SCHEMA, Curriculum, TestSet

__all__ = ["CONDITIONS", "CURRICULUM_SCHEMA", "PROFILES", "TESTS_SCHEMA", "Curriculum",
           "TestSet", "select_tests", "teach"]


def _check_int(name: str, value: Any, lo: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(value)


def _restrict(dom: Domain, envs: Any) -> Any:
    """`dom` restricted to `envs` (None: all of them, unchanged)."""
    if envs is None:
        return dom
    from cfteach.domains.selection import subset

    return subset(dom, envs)


class _Ticker:
    """A tqdm bar on stderr (only when asked and stderr is a terminal)."""

    def __init__(self, enabled: bool, total: int | None, desc: str) -> None:
        self.bar = None
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=desc, file=sys.stderr, leave=False)

    def __call__(self, msg: str) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(msg)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def teach(domain: Domain | str, condition: str, *, profile: str = "default", seed: int = 0,
          human_models: int = 8, max_demos: int | None = None,
          proportion: float | None = None, unbounded_models: str | None = None,
          progress: bool = False, envs: Any = None, backend: str = "local",
          workers: int | None = None, scheduler: str | None = None,
          executor: Executor | None = None, known: Sequence[str] | str | None = None
          ) -> Curriculum:
    """The curriculum one condition shows (see the module docstring).

    `unbounded_models`: what a human model with unbounded values in an instance contributes
    there: ``"skip"`` nothing (the reference), ``"loops"`` the constraints that its positive
    loops are not rewarding (default profile); docs/profiles.md.
    `envs`: teach on these environments only (`cfteach.domains.subset`: a ``--envs``
    string, or indices / env codes); the JSON still names each one's original index and code.

    `backend`/`workers`/`scheduler` (as in `cfteach.parallel`; `workers` None = 1 process
    for the local backend) or a live `executor` spread each round's planning and geometry
    over workers; the curriculum is identical to the one-process run (docs/parallel.md).
    `known`: features whose weight the learner is told (None: the domain file's
    ``[beliefs] known``); every belief then lives on that slice (`cfteach.teaching.known`).
    """
    check_condition(condition)
    config = parallel_config(backend, workers, scheduler, executor)
    check_profile(profile)
    rule = check_unbounded(DEFAULT_UNBOUNDED[profile] if unbounded_models is None
                           else unbounded_models)
    _check_int("seed", seed, 0)
    _check_int("human_models", human_models, 1)
    dom = _restrict(resolve_domain(domain), envs)
    sl = make_slice(dom, known_names(dom, known), profile)
    ds = demo_set(dom, profile)
    require_untied(ds)  # a tie of w* leaves nothing to teach: a named error, not zeros
    k = ds.domain.max_demos if max_demos is None else _check_int("max_demos", max_demos, 1)
    p = default_proportion(profile, condition, dom.name) if proportion is None \
        else check_proportion(proportion)
    settings: dict[str, Any] = {"human_models": human_models, "max_demos": k, "proportion": p,
                                "unbounded_models": rule}
    if envs is not None:
        settings["envs"] = list(dom.env_indices)
    if sl is not None:  # written only when some weight is known (older JSON unchanged)
        settings["known"] = settings_entry(sl, dom)
    tick = _Ticker(progress, k, f"{dom.name} {condition}")
    try:
        if condition in ("counterfactual_only", "proposed"):
            from cfteach.teaching.counterfactual import counterfactual_curriculum

            with open_executor(config, executor) as ex:
                records, final, log = counterfactual_curriculum(
                    ds, feature_scaffolding=condition == "proposed",
                    human_models=human_models, max_demos=k, proportion=p, seed=seed,
                    unbounded=rule, tick=tick, executor=ex, sl=sl)
        else:
            from cfteach.teaching.baseline import baseline_curriculum

            for key in ("proportion", "human_models", "unbounded_models"):
                settings[key] = None  # written in every curriculum, null where unused
            with open_executor(config, executor) as ex:
                one_step_cache(ds, ex)  # the one costly, per-demo part
            records, final, log = baseline_curriculum(
                ds, feature_scaffolding=condition == "feature_only", max_demos=k, seed=seed,
                sl=sl)
    finally:
        tick.close()
    return Curriculum(domain=dom, condition=condition, profile=profile, seed=seed,
                      settings=settings, records=records, final_belief=final, demo_set=ds,
                      log=log)


def select_tests(domain: Domain | str, *, training: Iterable[Any] = (),
                 profile: str = "default", seed: int = 0, per_level: int = 6,
                 human_models: int = 8, include_candidates: bool = False,
                 unbounded_models: str | None = None, progress: bool = False,
                 envs: Any = None, backend: str = "local", workers: int | None = None,
                 scheduler: str | None = None, executor: Executor | None = None,
                 known: Sequence[str] | str | None = None) -> TestSet:
    """Tests of low / medium / high difficulty (Algorithm 2), excluding training demos.

    `envs`: choose among these environments only (as for `teach`).
    `known`: as in `teach` (the overlaps are then measured on the known-weight slice).
    `backend`/`workers`/`scheduler`/`executor`: as in `teach` (identical results).
    """
    from cfteach.teaching.testsel import select

    check_profile(profile)
    config = parallel_config(backend, workers, scheduler, executor)
    rule = check_unbounded(DEFAULT_UNBOUNDED[profile] if unbounded_models is None
                           else unbounded_models)
    _check_int("seed", seed, 0)
    _check_int("per_level", per_level, 0)
    _check_int("human_models", human_models, 1)
    dom = _restrict(resolve_domain(domain), envs)
    sl = make_slice(dom, known_names(dom, known), profile)
    ds = demo_set(dom, profile)
    require_untied(ds)  # a tie of w* leaves nothing to teach: a named error, not zeros
    tick = _Ticker(progress, 1, f"{dom.name} tests")
    try:
        with open_executor(config, executor) as ex:
            parts = select(ds, training=list(training), seed=seed, per_level=per_level,
                           human_models=human_models, unbounded=rule, executor=ex, sl=sl)
        tick("overlaps")
    finally:
        tick.close()
    settings = {"human_models": human_models, "per_level": per_level,
                "n_clusters": len(parts["cluster_centres"]),
                "all_optimal_actions_cap": 50, "unbounded_models": rule}
    if envs is not None:
        settings["envs"] = list(dom.env_indices)
    if sl is not None:
        settings["known"] = settings_entry(sl, dom)
    return TestSet(domain=dom, profile=profile, seed=seed, settings=settings,
                   include_candidates=include_candidates, demo_set=ds, **parts)
