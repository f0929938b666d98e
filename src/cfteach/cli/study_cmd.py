"""`cfteach serve` and `cfteach study init|export|progress`: run the user study."""

import json
import os
from pathlib import Path
from typing import Annotated

import typer

from cfteach.cli import _options as _opt

study_app = typer.Typer(help="Create a study folder, export its data, watch its progress.",
                        no_args_is_help=True)

DEFAULT_DOMAINS = ("delivery", "tiles", "skateboard")
_PAPER_CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")


def _sources_from_dir(src: Path, domains: list[str],  # noqa: ANN202
                      conditions: list[str] | None = None):
    from cfteach.domains import load
    from cfteach.study.build import CLOSED_LOOP, CONDITIONS, DomainSource

    out = []
    for name in domains:
        folder = src / name
        if not folder.is_dir():
            raise typer.BadParameter(f"{folder} does not exist (expected the output of "
                                     "`cfteach reproduce --out DIR`)")
        cur = {}
        for cond in [c for c in conditions or CONDITIONS if c != CLOSED_LOOP]:
            p = folder / f"{cond}.json"
            if not p.exists():
                raise typer.BadParameter(f"missing curriculum {p}")
            cur[cond] = json.loads(p.read_text())
        tp = folder / "tests.json"
        if not tp.exists():
            raise typer.BadParameter(f"missing test set {tp}")
        out.append(DomainSource(load(name), cur, json.loads(tp.read_text())))
    return out


def _read_consent(path: Path | None) -> str | None:
    if path is None:
        return None
    if not path.exists():
        raise typer.BadParameter(f"consent file {path} does not exist")
    html = path.read_text(encoding="utf-8")
    if "<script" in html.lower():
        raise typer.BadParameter(f"{path}: the consent text may not contain <script> "
                                 "(the page's Content-Security-Policy would block it anyway)")
    return html


@study_app.command("init")
def init(
    out: Path = typer.Option(..., "--out", "-o", help="Study folder to create."),
    source: Path | None = typer.Option(None, "--from", help="Output folder of `cfteach "
                                       "reproduce` (DIR/<domain>/<condition>.json, tests.json)."),
    toy: bool = typer.Option(False, "--toy", help="A tiny 3-domain study for trying things."),
    preview: bool = typer.Option(False, "--preview", help="Placeholder demonstrations and "
                                 "tests on the real domains (not the paper's), to preview."),
    domains: Annotated[list[str] | None, _opt.domain_list(", ".join(DEFAULT_DOMAINS))] = None,
    profile: str = typer.Option("default", help="Teaching profile when generating."),
    seed: int = typer.Option(0, help="Seed when generating curricula and tests."),
    title: str = typer.Option("Machine Teaching Study", help="Page title."),
    completion_code: str = typer.Option("COMPLETED", help="Prolific completion code."),
    screened_out_code: str = typer.Option("SCREENED", help="Code for screened-out people."),
    no_consent_code: str = typer.Option("NOCONSENT", help="Code for people who decline "
                                        "consent (Prolific asks them to return the study)."),
    completion_url: str = typer.Option("https://app.prolific.com/submissions/complete?cc=",
                                       help="Redirect target; the code is appended. '' = none."),
    demo_step_ms: int = typer.Option(500, help="Milliseconds per demonstration step (the "
                                     "server counts a play once it lasted about steps x this)."),
    cutoff_minutes: float = typer.Option(30.0, help="An idle session stops counting toward "
                                         "its assignment cell after this long."),
    consent: Path | None = typer.Option(None, "--consent", help="HTML file with your consent "
                                        "text (no scripts), shown above the check boxes."),
    conditions: list[str] | None = typer.Option(
        None, "--condition", "-c", help="Conditions to assign: any of the paper's four and "
        f"closed_loop ({_opt.LIST_NOTE}). Default: the paper's four."),
    teacher: list[str] = typer.Option(None, "--teacher", help="closed_loop teacher settings "
                                      "as field=value (comma-separated or repeated), e.g. "
                                      "max_items=12; see docs/closed-loop.md."),
    force: bool = typer.Option(False, "--force", help="Replace study.json even when the "
                               "folder's study.db holds sessions; teach a domain whose size "
                               "estimate exceeds the free memory."),
    known: str | None = typer.Option(None, "--known", help="When generating: features whose "
                                     "weight the learner is told, comma-separated (e.g. step; "
                                     "'none': none); default: each domain file's [beliefs] "
                                     "known."),
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """Write a study folder (study.json) from curricula and test sets."""
    from cfteach.cli import _progress
    from cfteach.cli._common import check_out_dir, fail, study_sessions
    from cfteach.cli._lists import split_list
    from cfteach.cli.simulate_cmd import _teacher_settings
    from cfteach.study.build import (
        check_conditions,
        init_study,
        preview_sources,
        teaching_sources,
        toy_sources,
    )

    _progress.set_quiet(quiet)
    check_out_dir(out)
    n_sessions = study_sessions(f"sqlite:///{out / 'study.db'}")
    if n_sessions and not force:
        fail(f"--out {out}: its study.db holds {n_sessions} session(s) of participants; "
             "replacing study.json would detach them from their study: choose another "
             "folder, or pass --force")

    names = split_list(domains) or list(DEFAULT_DOMAINS)
    try:
        chosen = check_conditions(split_list(conditions) or list(_PAPER_CONDITIONS))
        settings = _teacher_settings([x for t in teacher or [] for x in t.split(",") if x])
    except ValueError as e:
        from cfteach.cli._common import did_you_mean
        from cfteach.study.build import ALL_CONDITIONS

        bad = [c for c in split_list(conditions) or [] if c not in ALL_CONDITIONS]
        fail(str(e) + (did_you_mean(bad[0], ALL_CONDITIONS) if bad else ""))
    if not (toy or preview or source is not None):  # teaching here: check domains first
        from cfteach.cli._common import check_known, load_domain

        for name in names:
            check_known(load_domain(name, force=force), known)
    elif known is not None:
        fail("--known applies when teaching here (not with --toy, --preview or --from)")
    try:
        if toy:
            sources = toy_sources()
        elif preview:
            sources = preview_sources(names, seed=seed)
        elif source is not None:
            sources = _sources_from_dir(source, names, chosen)
        else:
            sources = teaching_sources(names, profile=profile, seed=seed,
                                       progress=_progress.enabled(), known=known)
        path = init_study(out, sources, title=title, completion_code=completion_code,
                          screened_out_code=screened_out_code, no_consent_code=no_consent_code,
                          completion_url=completion_url,
                          demo_step_ms=demo_step_ms, cutoff_minutes=cutoff_minutes,
                          consent_html=_read_consent(consent), conditions=chosen,
                          teacher=settings)
    except ValueError as e:
        fail(str(e))
    typer.echo(f"wrote {path}")


@study_app.command("export")
def export(
    study: Annotated[Path, _opt.study()] = Path("study"),
    db: Annotated[str | None, _opt.db()] = None,
    out: Path = typer.Option(..., "--out", "-o", help="Folder for the CSV files."),
    include_previews: bool = typer.Option(False, help="Also export preview/test sessions."),
) -> None:
    """Write tidy CSVs (participants, test responses, Likert, demo views) + dictionary."""
    from cfteach.cli._common import check_out_dir, fail, study_sessions
    from cfteach.study.export import export_csv

    check_out_dir(out)
    db = db or f"sqlite:///{study / 'study.db'}"
    from cfteach.cli._checks import check_db_url

    check_db_url(db, must_exist=True)  # export never creates a database
    if study_sessions(db) is None:
        fail(f"--db {db}: not a cfteach study database (no sessions table)")

    counts = export_csv(db, out, include_previews=include_previews)
    for name, n in counts.items():
        typer.echo(f"{out / name}: {n} rows")


@study_app.command("progress")
def progress(
    study: Annotated[Path, _opt.study()] = Path("study"),
    db: Annotated[str | None, _opt.db()] = None,
) -> None:
    """Print how full each assignment cell is."""
    from cfteach.study.config import load_study
    from cfteach.study.db import make_engine, upgrade
    from cfteach.study.service import StudyService

    if not (study / "study.json").is_file():
        typer.echo(f"Error: no study at {study / 'study.json'}: create one with "
                   "`cfteach study init`", err=True)
        raise typer.Exit(2)
    if db is not None:
        from cfteach.cli._checks import check_db_url

        check_db_url(db)
    engine = make_engine(db or f"sqlite:///{study / 'study.db'}")
    upgrade(engine)
    p = StudyService(engine, load_study(study)).progress()
    typer.echo(f"study {p['study_version']}: {p['status']} (previews: {p['previews']}; in "
               f"progress on older versions: {p['older_versions_in_progress']})")
    for c in p["cells"]:
        typer.echo(f"{c['condition']:<20} {c['domain_order']:<28} set {c['test_set']}  "
                   f"occupied {c['occupied']}  completed {c['completed']}")


@study_app.command("screenshots")
def screenshots(
    study: Path = typer.Option(Path("study"), "--study", help="Study folder."),
    out: Path = typer.Option(Path("screenshots"), "--out", "-o",
                             help="Folder for the PNG files."),
    prefix: str = typer.Option("study-", help="File name prefix."),
    chromium: str = typer.Option("/usr/bin/chromium", help="Chromium executable."),
) -> None:
    """Save a PNG of every kind of page (headless Chromium, throw-away database)."""
    from cfteach.cli._common import check_out_dir
    from cfteach.study.screenshots import take_screenshots

    check_out_dir(out)

    for p in take_screenshots(study, out, prefix=prefix, chromium=chromium):
        typer.echo(str(p))


def serve(
    study: Path = typer.Option(Path("study"), "--study", help="Study folder from "
                               "`cfteach study init`."),
    db: str | None = typer.Option(None, "--db", help="Database URL (default: SQLite file "
                                  "study.db in the study folder; postgresql+psycopg://...)."),
    host: str = typer.Option("127.0.0.1", help="Interface to listen on."),
    port: int = typer.Option(8000, help="Port."),
    researcher_token: str | None = typer.Option(
        None, envvar="CFTEACH_RESEARCHER_TOKEN",
        help="Token for /researcher (random if unset; printed at start)."),
    sessions_per_minute: int = typer.Option(120, help="New sessions per client address per "
                                            "minute (0 = no limit)."),
    events_per_minute: int = typer.Option(600, help="Events per session per minute "
                                          "(0 = no limit)."),
    auth_failures_per_minute: int = typer.Option(
        60, help="Failed authentications (unknown or malformed session tokens, resumes "
        "without proof) per client address per minute before that address gets 429 "
        "(0 = no limit)."),
    forwarded_allow_ips: str = typer.Option(
        "", help="Reverse proxies whose X-Forwarded-For is trusted (comma-separated addresses "
        "or networks, '*' = any; default: none, not even loopback), so rate limits see "
        "participants' addresses, not the proxy's."),
    new_version: bool = typer.Option(
        False, "--new-version", help="Start even though sessions are in progress on an "
        "older study file this database does not hold (they can then not finish)."),
    quiet: Annotated[bool, _opt.quiet()] = False,
    states_per_minute: int = typer.Option(120, help="Page reads (GET /api/state) per "
                                          "session per minute (0 = no limit)."),
    decision_workers: int = typer.Option(
        2, min=0, max=64, help="Worker processes deciding closed-loop items (0 = a thread "
        "of the server process)."),
    allow_async_commit: bool = typer.Option(
        False, "--allow-async-commit", help="Run on a PostgreSQL database with "
        "synchronous_commit=off (acknowledged answers could be lost in a crash)."),
) -> None:
    """Run the study server (participants open /?PROLIFIC_PID=...&STUDY_ID=...&SESSION_ID=...)."""
    import secrets

    from cfteach.cli import _progress
    from cfteach.cli._checks import check_db_url, check_port

    _progress.set_quiet(quiet)
    if not (study / "study.json").is_file():
        typer.echo(f"Error: no study at {study / 'study.json'}: create one with "
                   f"`cfteach study init --out {study}`", err=True)
        raise typer.Exit(2)
    check_port(host, port)  # each one line, before anything is printed or started
    if db is not None:
        check_db_url(db)

    import uvicorn

    from cfteach.study.config import StudyError
    from cfteach.study.livesrv import server_config, settle_heap
    from cfteach.study.server import create_app

    token = researcher_token or secrets.token_urlsafe(16)
    try:
        with _progress.busy("preparing the study"):
            app = create_app(study, db, researcher_token=token,
                             sessions_per_minute=sessions_per_minute,
                             events_per_minute=events_per_minute,
                             auth_failures_per_minute=auth_failures_per_minute,
                             states_per_minute=states_per_minute,
                             decision_workers=decision_workers,
                             allow_async_commit=allow_async_commit, new_version=new_version)
    except StudyError as e:
        typer.echo(f"Error: {e}", err=True)
        raise typer.Exit(1) from None
    settle_heap()
    typer.echo(f"researcher page: http://{host}:{port}/researcher?token={token}", err=True)
    config = server_config(app, host=host, port=port, forwarded_allow_ips=forwarded_allow_ips,
                           log_level=os.environ.get("CFTEACH_LOG", "info"))
    uvicorn.Server(config).run()


def register(app: typer.Typer) -> None:
    """Add this module's commands to the `cfteach` app."""
    app.command("serve")(serve)
    app.add_typer(study_app, name="study")
