"""The main job: every condition's curriculum and the test set for each domain, written as
JSON, then every picture and the HTML report (`cfteach reproduce`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path

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
) -> tuple[dict[str, DomainResults], Path | None]:
    """Teach every condition and select tests for each domain; write JSON, pictures, report.

    Returns the results and the path of `index.html` (None with `report=False`).
    """
    from tqdm.auto import tqdm

    from cfteach import domains as dom
    from cfteach import teaching
    from cfteach.bec.demos import check_profile

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
    for name, domain in loaded.items():
        res = DomainResults()
        trained = []
        for cond in conditions:
            bar.set_postfix_str(f"{name}: {cond}")
            cur = teaching.teach(domain, cond, profile=profile, seed=seed)
            trained.append(cur)
            res.curricula[cond] = cur.to_json()
            bar.update()
        bar.set_postfix_str(f"{name}: tests")
        tests = teaching.select_tests(domain, training=tuple(trained), profile=profile, seed=seed)
        res.tests = tests.to_json()
        bar.update()
        results[domain.name] = res
        write_results(out, {domain.name: res})  # keep what is done even if a later one fails
    bar.close()
    seconds = time.perf_counter() - started

    meta = {
        "domains": list(results),
        "conditions": list(conditions),
        "profile": profile,
        "seed": seed,
        "seconds": seconds,
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
