"""`cfteach export minari`: the robot's demonstrations and people's test answers as Minari
datasets (docs/ecosystem.md). Heavy imports happen inside the commands."""

import json
import os
from pathlib import Path
from typing import Annotated

import typer

from cfteach.cli import _options as _opt

export_app = typer.Typer(help="Write cfteach data in other tools' formats (docs/ecosystem.md).",
                         no_args_is_help=True)
minari_app = typer.Typer(help="Minari datasets (offline RL / IRL), one per domain.",
                         no_args_is_help=True)
export_app.add_typer(minari_app, name="minari")

_ROOT_HELP = "Minari root folder (default: $MINARI_DATASETS_PATH, else ~/.minari/datasets)."


def _fail(message: str) -> None:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(2)


def _load_domain(name_or_path: str):  # noqa: ANN202 - a cfteach Domain
    from cfteach import domains

    try:
        return domains.load(name_or_path)
    except (ValueError, OSError, KeyError) as e:
        _fail(f"domain {name_or_path!r}: {e}")


def _domain_arg(name_or_path: str, domain) -> str | None:  # noqa: ANN001
    """How a dataset reader loads the domain: nothing for built-ins, else the file's path."""
    from cfteach import domains

    if domain.name in domains.builtin_names() and name_or_path == domain.name:
        return None
    return str(Path(name_or_path).resolve())


def _check_root(root: Path | None) -> None:
    """Before any work: the Minari root can be written (--root, else Minari's own)."""
    from cfteach.cli._common import check_out_dir

    if root is not None:
        check_out_dir(root, "--root")
        return
    env = os.environ.get("MINARI_DATASETS_PATH")
    check_out_dir(Path(env) if env else Path.home() / ".minari" / "datasets",
                  "MINARI_DATASETS_PATH" if env else "the Minari root")


def _check_new(dataset_ids: list[str], root: Path | None, force: bool) -> None:
    """Before any work: refuse to replace a dataset without --force."""
    from cfteach.ecosystem import dataset_exists

    for dataset_id in dataset_ids:
        try:
            there = dataset_exists(dataset_id, root)
        except ImportError as e:
            _fail(str(e))
        if there and not force:
            _fail(f"dataset {dataset_id!r} exists already (--force replaces it)")


def _write(episodes, dataset_id: str, domain, domain_arg, root, description: str,  # noqa: ANN001
           force: bool, check: bool) -> None:
    from cfteach.cli import _progress
    from cfteach.ecosystem import check_replay, write_dataset

    try:
        with _progress.busy(f"writing {dataset_id}"):
            ds = write_dataset(episodes, dataset_id, domain, domain_arg=domain_arg, root=root,
                               description=description, force=force)
        checked = check_replay(ds, progress=_progress.enabled()) if check else None
    except (ValueError, ImportError) as e:
        _fail(str(e))
    typer.echo(f"{dataset_id}: {ds.total_episodes} episodes, {ds.total_steps} steps"
               + (f"; all {checked} replay to their rewards" if check else ""))


@minari_app.command("demos")
def demos(
    domain: str = typer.Argument(..., help="Built-in domain name or domain file."),
    curriculum: list[Path] = typer.Option(  # noqa: B006 - typer's list option
        [], "--curriculum", help="Curriculum JSON (cfteach teach / reproduce output); "
        "repeat for several. Without it: every candidate demonstration."),
    instances: str = typer.Option("", help="Candidates only: comma-separated instance "
                                  "indices to keep (default all; see also --envs)."),
    envs: str | None = typer.Option(None, "--envs", help="Candidates only: plan and export "
                                    "these environments only (indices, env codes, slices "
                                    "such as 0::16; docs/domains.md)."),
    dataset_id: str = typer.Option("", help="Dataset id (default cfteach/DOMAIN/curricula-v0 "
                                   "or cfteach/DOMAIN/candidates-v0)."),
    root: Path | None = typer.Option(None, help=_ROOT_HELP),
    force: bool = typer.Option(False, "--force", help="Replace an existing dataset of that id."),
    check: bool = typer.Option(True, help="Replay every episode after writing."),
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """The robot's demonstrations (rewards under w*) as a Minari dataset."""
    from cfteach.cli import _progress
    from cfteach.ecosystem import candidate_episodes, curriculum_episodes

    _progress.set_quiet(quiet)
    _check_root(root)
    dom = _load_domain(domain)
    if envs is not None:
        if curriculum:
            _fail("--envs selects candidate demonstrations; a curriculum already names its "
                  "environments (drop --envs or --curriculum)")
        if instances.strip():
            _fail("give --envs or --instances, not both")
        from cfteach.domains.selection import subset

        try:
            dom = subset(dom, envs)
        except ValueError as e:
            _fail(f"--envs: {e}")
    kind = "curricula" if curriculum else "candidates"
    _check_new([dataset_id or f"cfteach/{dom.name}/{kind}-v0"], root, force)  # before work
    try:
        if curriculum:
            episodes = []
            for path in curriculum:
                try:
                    data = json.loads(path.read_text(encoding="utf-8"))
                except (OSError, json.JSONDecodeError) as e:
                    _fail(f"{path}: {e}")
                episodes += curriculum_episodes(dom, data)
            kind, what = "curricula", f"{len(curriculum)} curriculum file(s)"
        else:
            keep = [int(x) for x in instances.split(",") if x.strip()] or None
            episodes = candidate_episodes(dom, env_indices=keep, progress=_progress.enabled())
            kind, what = "candidates", "every candidate demonstration"
    except ValueError as e:
        _fail(str(e))
    _write(episodes, dataset_id or f"cfteach/{dom.name}/{kind}-v0", dom,
           _domain_arg(domain, dom), root,
           f"cfteach: the robot's demonstrations in domain {dom.name} ({what}); "
           "rewards are w* . phi", force, check)


@minari_app.command("answers")
def answers(
    study: Path = typer.Option(..., "--study", help="Study folder (cfteach study init)."),
    export: Path = typer.Option(..., "--export", help="Its export (cfteach study export)."),
    domains: Annotated[list[str] | None, _opt.domain_list(
        "all the study's; a domain file path for user domains")] = None,
    status: list[str] | None = typer.Option(None, "--status", help="Participant statuses to "
                                            f"keep, e.g. completed ({_opt.LIST_NOTE}). "
                                            "Default: all exported."),
    prefix: str = typer.Option("cfteach", help="Datasets are PREFIX/DOMAIN/answers-v0."),
    root: Path | None = typer.Option(None, help=_ROOT_HELP),
    force: bool = typer.Option(False, "--force", help="Replace existing datasets of those ids."),
    check: bool = typer.Option(True, help="Replay every episode after writing."),
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """People's test answers (one episode per participant x test) as Minari datasets."""
    from cfteach.cli import _progress
    from cfteach.cli._lists import split_list
    from cfteach.ecosystem import answer_episodes
    from cfteach.ecosystem.study_files import read_study

    _progress.set_quiet(quiet)
    _check_root(root)
    try:
        names = split_list(domains) or read_study(study)["domains"]
    except ValueError as e:
        _fail(str(e))
    keep = split_list(status)
    loaded = [(name, _load_domain(name)) for name in names]
    _check_new([f"{prefix}/{dom.name}/answers-v0" for _, dom in loaded], root, force)
    for name, dom in loaded:
        try:
            episodes = answer_episodes(dom, study, export, statuses=keep)
        except ValueError as e:
            _fail(str(e))
        if not episodes:
            typer.echo(f"{dom.name}: no answers to write")
            continue
        _write(episodes, f"{prefix}/{dom.name}/answers-v0", dom, _domain_arg(name, dom), root,
               f"cfteach user study: people's test answers in domain {dom.name}, one episode "
               "per participant x test; rewards are w* . phi", force, check)


@minari_app.command("check")
def check_cmd(
    dataset_id: str = typer.Argument(..., help="A local Minari dataset id."),
    root: Path | None = typer.Option(None, help=_ROOT_HELP),
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """Replay every episode of a dataset in its recovered environment."""
    from cfteach.cli import _progress
    from cfteach.ecosystem import check_replay, load_dataset

    _progress.set_quiet(quiet)
    try:
        n = check_replay(load_dataset(dataset_id, root), progress=_progress.enabled())
    except (ValueError, ImportError, FileNotFoundError) as e:
        _fail(str(e))
    if n == 0:
        typer.echo(f"Error: {dataset_id}: the dataset holds no episodes (an interrupted "
                   "export?); write it again with --force", err=True)
        raise typer.Exit(1)
    typer.echo(f"{dataset_id}: all {n} episodes replay to their rewards")


def register(app: typer.Typer) -> None:
    """Add the `cfteach export` command group to the app."""
    app.add_typer(export_app, name="export")
