"""The main job: every condition's curriculum and the test set for each domain, written as
JSON, then every picture and the HTML report (`cfteach reproduce`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

from cfteach.report.build import (
    CONDITIONS,
    DomainResults,
    build_report,
    default_layouts,
    write_results,
    write_run,
)


def reproduce(
    out_dir: str | Path,
    domains: Sequence[str] | None = None,
    *,
    profile: str = "default",
    seed: int = 0,
    conditions: Sequence[str] = CONDITIONS,
    report: bool = True,
    progress: bool | None = None,
    backend: str = "local",
    workers: int | None = 1,
    scheduler: str | None = None,
    known: Sequence[str] | str | None = None,
) -> tuple[dict[str, DomainResults], Path | None]:
    """Teach every condition and select tests for each domain; write JSON, pictures, report.

    Returns the results and the path of `index.html` (None with `report=False`).
    `backend`/`workers`/`scheduler` (`cfteach.parallel`): with more than one worker the
    domains are taught side by side, one domain per task (the same JSON as one process);
    `workers=None` uses every local core. `known`: features whose weight every learner is
    told (as `teaching.teach`; None: each domain file's ``[beliefs] known``).
    """
    from tqdm.auto import tqdm

    from cfteach import domains as dom
    from cfteach.bec.demos import check_profile
    from cfteach.parallel import Executor, ParallelConfig

    names = list(domains) if domains else list(dom.builtin_names())
    check_profile(profile)  # before any work: the teacher's own check of the name
    unknown = [c for c in conditions if c not in CONDITIONS]
    if unknown:
        raise ValueError(f"unknown condition(s) {unknown}; use {', '.join(CONDITIONS)}")
    loaded = {name: dom.load(name) for name in names}  # fail fast on a bad name or file
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    show = sys.stderr.isatty() if progress is None else progress

    started = time.perf_counter()
    results: dict[str, DomainResults] = {}
    bar = tqdm(
        total=len(names) * (len(conditions) + 1),
        desc="reproduce",
        disable=not show,
        file=sys.stderr,
    )
    config = ParallelConfig(backend=backend, n_workers=workers, scheduler=scheduler)
    if known is not None:  # every domain must have these features: a named error before work
        from cfteach.teaching.known import known_names

        for d in loaded.values():
            known_names(d, known)
    job = partial(_teach_domain, profile=profile, seed=seed, conditions=tuple(conditions),
                  known=known)
    with Executor(config) as ex:
        if len(loaded) > 1 and (backend != "local" or ex.n_workers > 1):
            bar.set_postfix_str(f"{len(loaded)} domains on {ex.n_workers} workers")
            # built-ins go by name, files by path: each worker loads its own domain
            for name, res in ex.map(job, list(loaded)):
                results[name] = res
                write_results(out, {name: res})
                bar.update(len(conditions) + 1)
        else:
            for domain in loaded.values():
                res = _teach_domain(domain, profile=profile, seed=seed,
                                    conditions=tuple(conditions), bar=bar, known=known)[1]
                results[domain.name] = res
                write_results(out, {domain.name: res})  # keep what is done if a later fails
    bar.close()
    seconds = time.perf_counter() - started

    meta = {
        "domains": list(results),
        "conditions": list(conditions),
        "profile": profile,
        "seed": seed,
        "seconds": seconds,
        **({"known": known if isinstance(known, str) else list(known)}
           if known is not None else {}),
        # user domains: where to find their files again (report-only rebuilds)
        "domain_files": {
            d.name: str(Path(d.source).resolve())
            for d in loaded.values()
            if d.name not in dom.builtin_names() and Path(d.source).is_file()
        },
    }
    write_run(out, meta)
    index = None
    if report:
        layouts = default_layouts({d.name: d for d in loaded.values()})
        index = build_report(out, results, meta=meta, layouts=layouts, progress=show)
    return results, index


def _teach_domain(domain: Any, *, profile: str, seed: int, conditions: tuple[str, ...],
                  bar: Any = None, known: Sequence[str] | str | None = None
                  ) -> tuple[str, DomainResults]:
    """Every condition's curriculum and the tests of one domain (a name, a path or a
    `Domain`), as JSON; module-level so a worker process can run it (k-means runs on one
    thread wherever it runs, `teaching.common.fit_kmeans`, so workers write the same JSON).
    """
    from cfteach import domains as dom
    from cfteach import teaching

    if isinstance(domain, str):
        domain = dom.load(domain)
    res = DomainResults()
    trained = []
    for cond in conditions:
        if bar is not None:
            bar.set_postfix_str(f"{domain.name}: {cond}")
        cur = teaching.teach(domain, cond, profile=profile, seed=seed, known=known)
        trained.append(cur)
        res.curricula[cond] = cur.to_json()
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.set_postfix_str(f"{domain.name}: tests")
    tests = teaching.select_tests(domain, training=tuple(trained), profile=profile, seed=seed,
                                  known=known)
    res.tests = tests.to_json()
    if bar is not None:
        bar.update()
    return domain.name, res
