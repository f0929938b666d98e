"""A self-contained HTML report of curricula and test sets, built from their JSON dicts.

`build_report(out_dir, results)` takes already-computed results (the `cfteach.curriculum/1`
and `cfteach.tests/1` dicts of docs/schemas.md), so it runs on files written earlier, on
hand-made fixtures, or right after `cfteach reproduce` computes them. It writes the pictures
under `<out_dir>/<domain>/img/` and `<out_dir>/index.html` (relative links only, no scripts,
no network).
"""

from cfteach.report.build import (
    CONDITIONS,
    DomainResults,
    build_report,
    load_meta,
    load_results,
    write_results,
    write_run,
)

__all__ = [
    "CONDITIONS",
    "DomainResults",
    "build_report",
    "load_meta",
    "load_results",
    "write_results",
    "write_run",
]
