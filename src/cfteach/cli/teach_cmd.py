"""`cfteach teach` (a curriculum for one condition) and `cfteach tests` (Algorithm 2).

Both print JSON (docs/schemas.md) or write it with --out. Heavy imports happen inside the
commands so `cfteach --help` stays fast.
"""

import json
from pathlib import Path
from types import ModuleType
from typing import Annotated, Any

import typer

from cfteach.cli import _options as _opt
from cfteach.cli import _progress
from cfteach.cli._common import (
    ENVS_HELP,
    check_known,
    check_out_file,
    check_positive,
    did_you_mean,
    fail,
    load_domain,
)

_PROFILE_HELP = "reference: the authors' deterministic choices; default: ours (docs/profiles.md)."
_UNBOUNDED_HELP = ("Human models with unbounded values: skip (give nothing, the reference and "
                   "its profile) or loops (their positive loops are not rewarding; default "
                   "profile).")


_KNOWN_HELP = ("Features whose weight the learner is told, comma-separated (e.g. step; "
               "'none': none): beliefs live on that slice (docs/teaching.md). Default: the "
               "domain file's [beliefs] known.")


_FORCE_HELP = "Go on even when the size estimate exceeds the free memory."
_BACKEND_HELP = ("Where each round's planning and geometry run: local, dask or ray "
                 "(docs/parallel.md); the result is the same.")
_SCHEDULER_HELP = "Dask scheduler / Ray address (default: start a local cluster)."


def check_parallel(backend: str, workers: int | None, scheduler: str | None) -> None:
    """One-line errors for bad --backend/--workers/--scheduler before any work."""
    from cfteach.parallel import BACKENDS

    _check_choice(backend, BACKENDS, "--backend")
    check_positive(workers, "--workers")
    if scheduler is not None and backend == "local":
        fail("--scheduler needs --backend dask or ray (the local backend has no scheduler)")


def _emit(data: dict[str, Any], out: Path | None) -> None:
    text = json.dumps(data, indent=2)
    if out is None:
        typer.echo(text)
        return
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text + "\n")
    except OSError as exc:
        fail(f"--out {out}: cannot write: {exc.strerror or exc}", code=1)
    typer.echo(f"wrote {out}", err=True)


def _check_choice(value: str, choices: tuple[str, ...], option: str) -> None:
    if value not in choices:
        fail(f"{option}: unknown value {value!r} (allowed: {', '.join(choices)})"
             + did_you_mean(value, choices))


def _envs_of(dom: Any, envs: str | None) -> list[int] | None:
    """The chosen environments' indices for the JSON's settings (None without --envs)."""
    return None if envs is None else list(dom.env_indices)


def _show(cur_json: dict[str, Any], domain: Any) -> None:
    """Each demonstration as text, with the renderer if it is available."""
    render: ModuleType | None
    try:
        from cfteach import render as render_module
    except ImportError:  # pragma: no cover - render is part of the package
        render = None
    else:
        render = render_module
    labels = dict(zip(domain.feature_names, domain.feature_labels, strict=True))

    def masked(name: str | None) -> str:  # the legend's word first, the JSON's name after
        if name is None:
            return "none"
        label = labels.get(name, name).lower()
        return label if label == name else f"{label} ({name})"

    for i, demo in enumerate(cur_json["demos"], 1):
        head = (f"demo {i}: env {demo['env_code']}  gain {demo['knowledge_gain']:.3f}  "
                f"mask {masked(demo['masked_feature'])}  actions {' '.join(demo['actions'])}")
        typer.echo(head, err=True)
        if render is not None:
            inst = domain.instance(demo["env_index"])
            layout = render.layout_from_instance(inst)
            typer.echo(render.demo_text(layout, demo["states"], actions=demo["actions"],
                                        action_specs=domain.action_specs), err=True)


def register(app: typer.Typer) -> None:
    """Add `cfteach teach` and `cfteach tests` to the app."""

    @app.command("teach")
    def teach_cmd(
        domain: Annotated[str, typer.Argument(help="Built-in domain name or domain file.")],
        condition: Annotated[str, typer.Option(
            "--condition", "-c",
            help="baseline, feature_only, counterfactual_only or proposed.")] = "proposed",
        profile: Annotated[str, typer.Option(help=_PROFILE_HELP)] = "default",
        seed: Annotated[int, typer.Option(help="Seed of everything random.")] = 0,
        human_models: Annotated[int, typer.Option(
            "--human-models", "-m", help="Human models sampled per round.")] = 8,
        max_demos: Annotated[int | None, typer.Option(
            help="Most demonstrations to show (default: the domain file's [teaching] "
                 "max_demos; the study's 5/5/7, else 5).")] = None,
        proportion: Annotated[float | None, typer.Option(
            help="Pick the gain closest to this share of the best, in (0, 1] (default: "
                 "1; the reference profile uses 0.7 for counterfactual_only in delivery "
                 "and skateboard).")] = None,
        unbounded_models: Annotated[str | None, typer.Option(
            help=_UNBOUNDED_HELP)] = None,
        out: Annotated[Path | None, typer.Option("--out", "-o",
                                                 help="Write the JSON here.")] = None,
        show: Annotated[bool, typer.Option(
            help="Also draw each demonstration as text (on stderr).")] = False,
        force: Annotated[bool, typer.Option("--force", help=_FORCE_HELP)] = False,
        envs: Annotated[str | None, typer.Option("--envs", help=ENVS_HELP)] = None,
        backend: Annotated[str, typer.Option(help=_BACKEND_HELP)] = "local",
        workers: Annotated[int | None, _opt.workers()] = None,
        scheduler: Annotated[str | None, typer.Option(help=_SCHEDULER_HELP)] = None,
        known: Annotated[str | None, typer.Option("--known", help=_KNOWN_HELP)] = None,
        quiet: Annotated[bool, _opt.quiet()] = False,
    ) -> None:
        """Choose the demonstrations one study condition shows; print the curriculum JSON."""
        from cfteach.bec import UNBOUNDED_RULES
        from cfteach.bec.demos import PROFILES
        from cfteach.teaching import CONDITIONS, teach
        from cfteach.teaching.common import check_condition

        if condition == "closed_loop":  # a known condition, but no fixed curriculum
            try:
                check_condition(condition)
            except ValueError as exc:
                fail(f"--condition: {exc}")
        _check_choice(condition, CONDITIONS, "--condition")
        _check_choice(profile, PROFILES, "--profile")
        if unbounded_models is not None:
            _check_choice(unbounded_models, tuple(UNBOUNDED_RULES), "--unbounded-models")
        check_positive(max_demos, "--max-demos")
        check_positive(human_models, "--human-models")
        if seed < 0:
            fail(f"--seed must be 0 or more, got {seed}")
        if proportion is not None and not 0 < proportion <= 1:
            fail(f"--proportion must lie in (0, 1], got {proportion}")
        _progress.set_quiet(quiet)
        check_parallel(backend, workers, scheduler)
        check_out_file(out)
        dom = load_domain(domain, force=force, envs=envs)
        known_list = check_known(dom, known)
        try:
            cur = teach(dom, condition, profile=profile, seed=seed, known=known_list,
                        human_models=human_models, max_demos=max_demos,
                        proportion=proportion, unbounded_models=unbounded_models,
                        progress=_progress.enabled(), envs=_envs_of(dom, envs),
                        backend=backend, workers=workers, scheduler=scheduler)
        except (ValueError, TypeError) as exc:
            fail(str(exc))
        except (ConnectionError, RuntimeError) as exc:  # cluster unreachable, extra missing
            fail(f"--backend {backend}: {exc}", code=1)
        data = cur.to_json()
        _emit(data, out)
        if show:
            _show(data, cur.domain)

    @app.command("tests")
    def tests_cmd(
        domain: Annotated[str, typer.Argument(help="Built-in domain name or domain file.")],
        per_level: Annotated[int, typer.Option(
            help="Tests per difficulty level (fewer if a cluster is smaller).")] = 6,
        training: Annotated[list[Path] | None, typer.Option(
            "--training", "-t",
            help="Curriculum JSON file(s) whose demonstrations are not to be tests.")] = None,
        all_candidates: Annotated[bool, typer.Option(
            "--all", help="Also list every candidate with its overlap and cluster.")] = False,
        profile: Annotated[str, typer.Option(help=_PROFILE_HELP)] = "default",
        seed: Annotated[int, typer.Option(help="Seed of everything random.")] = 0,
        human_models: Annotated[int, typer.Option(
            "--human-models", "-m", help="Human models sampled from the posterior.")] = 8,
        unbounded_models: Annotated[str | None, typer.Option(
            help=_UNBOUNDED_HELP)] = None,
        out: Annotated[Path | None, typer.Option("--out", "-o",
                                                 help="Write the JSON here.")] = None,
        force: Annotated[bool, typer.Option("--force", help=_FORCE_HELP)] = False,
        envs: Annotated[str | None, typer.Option("--envs", help=ENVS_HELP)] = None,
        backend: Annotated[str, typer.Option(help=_BACKEND_HELP)] = "local",
        workers: Annotated[int | None, _opt.workers()] = None,
        scheduler: Annotated[str | None, typer.Option(help=_SCHEDULER_HELP)] = None,
        known: Annotated[str | None, typer.Option("--known", help=_KNOWN_HELP)] = None,
        quiet: Annotated[bool, _opt.quiet()] = False,
    ) -> None:
        """Pick low / medium / high difficulty tests (Algorithm 2); print the tests JSON."""
        from cfteach.bec import UNBOUNDED_RULES
        from cfteach.bec.demos import PROFILES
        from cfteach.teaching import select_tests

        check_positive(per_level, "--per-level")
        check_positive(human_models, "--human-models")
        _check_choice(profile, PROFILES, "--profile")
        if unbounded_models is not None:
            _check_choice(unbounded_models, tuple(UNBOUNDED_RULES), "--unbounded-models")
        if seed < 0:
            fail(f"--seed must be 0 or more, got {seed}")
        _progress.set_quiet(quiet)
        check_parallel(backend, workers, scheduler)
        check_out_file(out)
        curricula = []
        for path in training or []:
            try:
                curricula.append(json.loads(Path(path).read_text()))
            except OSError as exc:
                fail(f"--training {path}: cannot read it: {exc.strerror or exc}")
            except json.JSONDecodeError as exc:
                fail(f"--training {path}: not JSON ({exc.msg} at line {exc.lineno}); "
                     "expected a curriculum written by `cfteach teach`")
        dom = load_domain(domain, force=force, envs=envs)
        known_list = check_known(dom, known)
        try:
            ts = select_tests(dom, training=curricula, profile=profile, seed=seed,
                              known=known_list,
                              per_level=per_level, human_models=human_models,
                              include_candidates=all_candidates,
                              unbounded_models=unbounded_models,
                              progress=_progress.enabled(), envs=_envs_of(dom, envs),
                              backend=backend, workers=workers, scheduler=scheduler)
        except (ValueError, TypeError, KeyError) as exc:
            fail(str(exc))
        except (ConnectionError, RuntimeError) as exc:  # cluster unreachable, extra missing
            fail(f"--backend {backend}: {exc}", code=1)
        data = ts.to_json()
        for level, items in data["tests"].items():
            if len(items) < per_level:
                typer.echo(f"note: only {len(items)} {level}-difficulty candidates in their "
                           f"cluster (asked for {per_level})", err=True)
        _emit(data, out)
