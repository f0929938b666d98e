"""`cfteach reproduce`: the main job (all conditions, test selection, pictures, HTML report).

Heavy imports happen inside the command so `cfteach --help` stays fast.
"""

from pathlib import Path
from typing import Annotated

import typer

from cfteach.cli import _options as _opt
from cfteach.cli._lists import split_list


def reproduce(
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (JSON, pictures, index.html).")
    ] = Path("out/reproduce"),
    domains: Annotated[
        list[str] | None,
        _opt.domain_list("all built-ins"),
    ] = None,
    profile: Annotated[
        str, typer.Option(help="Settings profile: 'default' or 'reference' (docs/profiles.md).")
    ] = "default",
    seed: Annotated[int, typer.Option(help="Seed everything random is drawn from.")] = 0,
    report_only: Annotated[
        bool,
        typer.Option(
            "--report-only", help="Do not teach; rebuild the report from the JSON files in --out."
        ),
    ] = False,
    no_report: Annotated[
        bool, typer.Option("--no-report", help="Write the JSON files only.")
    ] = False,
    force: Annotated[bool, _opt.force()] = False,
    backend: Annotated[
        str, typer.Option(help="Where the domains are taught: local, dask or ray "
                               "(docs/parallel.md); the JSON is the same.")
    ] = "local",
    workers: Annotated[int | None, _opt.workers()] = None,
    scheduler: Annotated[
        str | None, typer.Option(help="Dask scheduler / Ray address (default: start a local "
                                      "cluster).")
    ] = None,
    known: Annotated[
        str | None, typer.Option("--known", help="Features whose weight the learner is told, "
                                                 "comma-separated (e.g. step; 'none': none); "
                                                 "default: each domain file's [beliefs] known.")
    ] = None,
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """Run every condition and test selection for the domains; write JSON, pictures and a
    self-contained index.html report."""
    from cfteach.bec.demos import PROFILES
    from cfteach.cli import _progress
    from cfteach.cli._common import (
        check_known,
        check_out_dir,
        did_you_mean,
        fail,
        load_domain,
    )
    from cfteach.cli.teach_cmd import check_parallel
    from cfteach.report import build_report, load_meta, load_results
    from cfteach.report.reproduce import reproduce as run

    _progress.set_quiet(quiet)
    if report_only:
        check_out_dir(out)  # the report is written into --out
        try:
            results = load_results(out)
        except (OSError, ValueError) as exc:
            raise typer.BadParameter(str(exc), param_hint="--out") from exc
        typer.echo(f"Report: {build_report(out, results, meta=load_meta(out))}")
        return
    if profile not in PROFILES:
        fail(f"--profile: unknown value {profile!r} (allowed: {', '.join(PROFILES)})"
             + did_you_mean(profile, PROFILES))
    if seed < 0:
        fail(f"--seed must be 0 or more, got {seed}")
    check_parallel(backend, workers, scheduler)
    check_out_dir(out)
    for name in split_list(domains) or []:  # every check before hours of work
        check_known(load_domain(name, force=force, sphere=not no_report), known)
    try:
        results, index = run(out, split_list(domains), profile=profile, seed=seed,
                             report=not no_report, backend=backend, workers=workers,
                             scheduler=scheduler, known=known,
                             progress=_progress.enabled())
    except (ValueError, FileNotFoundError) as exc:
        typer.echo(f"Error: {exc}", err=True)
        raise typer.Exit(2) from exc
    except (ConnectionError, RuntimeError) as exc:  # cluster unreachable, extra missing
        fail(f"--backend {backend}: {exc}", code=1)
    for name, res in results.items():
        n = ", ".join(f"{c} {len(cur['demos'])}" for c, cur in res.curricula.items())
        levels = res.tests["tests"] if res.tests else {}
        t = ", ".join(f"{lv} {len(v)}" for lv, v in levels.items())
        typer.echo(f"{name}: demonstrations {n}; tests {t}")
    typer.echo(f"JSON: {out}/<domain>/<condition>.json, {out}/<domain>/tests.json")
    if index is not None:
        typer.echo(f"Report: {index}")


def register(app: typer.Typer) -> None:
    """Add `cfteach reproduce` to the app."""
    app.command("reproduce")(reproduce)
