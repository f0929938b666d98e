"""`cfteach simulate`: compare teaching conditions with simulated learners (docs/simulate.md)."""

from pathlib import Path
from typing import Annotated

import typer

from cfteach.cli import _options as _opt
from cfteach.cli._lists import split_list


def register(app: typer.Typer) -> None:
    """Add this module's commands to the `cfteach` app."""

    @app.command("simulate")
    def simulate_cmd(
        domains: list[str] = typer.Option(
            None, "--domain", "-d",
            help="Domains (comma-separated or repeated): built-in names, TOML files, or "
                 "random:WxH:fF:nN:sS. Default: delivery,tiles,skateboard."),
        conditions: list[str] = typer.Option(
            None, "--condition", "-c",
            help="baseline, feature_only, counterfactual_only, proposed, closed_loop "
                 "(adaptive teaching; adds the proposed_equal_budget control) and 'none' "
                 "(no demonstrations). Default: the paper's four and none."),
        learner: list[str] = typer.Option(
            None, "--learner-model", "-l",
            help="Learner models: counterfactual, irl, noisy, inattentive, each optionally "
                 "with "
                 "field=value settings, e.g. noisy:temperature=0.1:human_models=3. "
                 "Default: counterfactual,noisy."),
        learners: int = typer.Option(32, "--learners", "-n", min=1,
                                     help="How many simulated learners per condition and model."),
        seeds: int = typer.Option(1, "--replications", "-k", min=1,
                                  help="How many replications: teaching and tests are redone "
                                       "for each, on its own seed."),
        seed: int = typer.Option(0, "--seed", min=0, help="Root seed of the learners' draws."),
        candidates: bool = typer.Option(
            False, "--all", help="Also give every candidate test (not just the selected)."),
        source: Path = typer.Option(
            None, "--from", help="Read curricula/tests from a `cfteach reproduce` folder "
                                 "instead of teaching."),
        profile: str = typer.Option("default", "--profile", help="Teaching profile."),
        human_models: int = typer.Option(8, "--human-models", min=1,
                                         help="Human models sampled by the teacher."),
        backend: str = typer.Option("local", "--backend", help="local, dask or ray."),
        workers: Annotated[int | None, _opt.workers()] = None,
        scheduler: str = typer.Option(None, "--scheduler",
                                      help="Dask scheduler / Ray address (default: start a "
                                           "local cluster)."),
        chunk: int = typer.Option(16, "--chunk", min=1,
                                  help="Learners per work chunk (results depend on it)."),
        teacher: list[str] = typer.Option(
            None, "--teacher",
            help="closed_loop teacher settings as field=value (comma-separated or repeated), "
                 "e.g. p_learn=0.7,max_items=30; see docs/closed-loop.md."),
        out: Path = typer.Option(Path("out/simulate"), "--out", "-o", help="Output folder."),
        force: Annotated[bool, _opt.force()] = False,
        quiet: Annotated[bool, _opt.quiet()] = False,
        known: str = typer.Option(None, "--known", help="Features whose weight the learner is "
                                  "told, comma-separated (e.g. step; 'none': none); default: "
                                  "each domain file's [beliefs] known."),
    ) -> None:
        """Teach simulated learners every condition's curriculum and test them: proportion
        optimal by difficulty x condition (95% CIs) and the H1 overlap-correctness
        correlation, as JSON, CSV and plots."""
        from cfteach.cli import _progress
        from cfteach.cli._common import check_known, check_out_dir, load_domain

        _progress.set_quiet(quiet)
        check_out_dir(out)  # before the work: a bad --out must not cost the whole sweep
        _check_names(split_list(conditions), split_list(learner))
        from cfteach.simulate.sweep import run_sweep
        for name in split_list(domains) or []:  # the domain checks and the size guard
            check_known(load_domain(name, force=force), known)
        try:
            settings = _teacher_settings(split_list(teacher))
            result = run_sweep(
                split_list(domains) or ["delivery", "tiles", "skateboard"],
                split_list(conditions), split_list(learner), n_learners=learners, seeds=seeds,
                include_candidates=candidates, source=source, profile=profile,
                human_models=human_models, seed=seed, backend=backend, n_workers=workers,
                scheduler=scheduler, chunk_learners=chunk, progress=_progress.enabled(),
                teacher=settings, known=known)
        except (ValueError, FileNotFoundError, ImportError, ConnectionError) as err:
            typer.echo(f"Error: {err}", err=True)
            raise typer.Exit(2) from None
        summ = result.write(out)
        _print_summary(summ)
        typer.echo(f"\nwrote {out}/results.json, answers.csv, beliefs.csv and "
                   f"{len(summ['figures'])} figures")


def _check_names(conditions: list[str] | None, learners: list[str] | None) -> None:
    """Unknown conditions and learner models: one line with a close match, before work."""
    from cfteach.cli._common import check_choice, did_you_mean, fail
    from cfteach.simulate.learners import LEARNER_MODELS
    from cfteach.simulate.sweep import NO_TEACHING, SWEEP_CONDITIONS

    allowed = (*SWEEP_CONDITIONS, NO_TEACHING)
    bad = [c for c in conditions or [] if c not in allowed]
    if bad:  # the sweep's own words, and a close match
        fail(f"unknown condition(s) {bad}; choose from {', '.join(allowed)}"
             + did_you_mean(bad[0], allowed))
    for spec in learners or []:
        check_choice(spec.split(":")[0], tuple(LEARNER_MODELS), "--learner-model")


def _teacher_settings(pairs: list[str] | None) -> dict:
    """``field=value`` pairs to typed closed-loop settings (ValueError names a bad pair)."""
    import dataclasses

    from cfteach.closedloop import TeacherSettings

    types = {f.name: f.type for f in dataclasses.fields(TeacherSettings)}
    out: dict = {}
    for pair in pairs or []:
        key, eq, value = pair.partition("=")
        if not eq or key not in types:
            raise ValueError(f"bad --teacher setting {pair!r}: write field=value with a field "
                             f"among {', '.join(types)}")
        try:
            if key == "zpd_band":
                lo, hi = value.split("/")
                out[key] = (float(lo), float(hi))
            elif key in ("rationality", "uptake", "disengaged", "confused"):  # grids: a/b/c
                out[key] = tuple(float(x) for x in value.split("/"))
            elif key in ("model", "probes", "confusion"):
                out[key] = value
            elif types[key] in ("int", int):
                out[key] = int(value)
            else:
                out[key] = float(value)
        except ValueError:
            raise ValueError(f"bad value {value!r} for --teacher {key} (zpd_band is "
                             f"written low/high, e.g. 0.3/1.0)") from None
    return out


def _print_summary(summ: dict) -> None:
    rows = summ["proportion_optimal"]
    if not rows:
        typer.echo("no selected tests were answered (empty test set)")
        return
    scope = "all" if any(r["domain"] == "all" for r in rows) else None
    for model in sorted({r["learner_model"] for r in rows}):
        typer.echo(f"\nlearner model: {model}   (proportion optimal [95% CI], "
                   f"domain: {scope or rows[0]['domain']})")
        typer.echo(f"  {'condition':22s} {'low':>20s} {'medium':>20s} {'high':>20s}")
        sel = [r for r in rows if r["learner_model"] == model
               and r["domain"] == (scope or r["domain"])]
        for cond in dict.fromkeys(r["condition"] for r in sel):
            cells = {r["difficulty"]: r for r in sel if r["condition"] == cond}
            txt = "".join(
                f" {c['proportion_optimal']:.2f} [{c['ci_low']:.2f},{c['ci_high']:.2f}]".rjust(21)
                if (c := cells.get(lv)) else " " * 21 for lv in ("low", "medium", "high"))
            typer.echo(f"  {cond:22s}{txt}")
    regret = summ.get("regret", {})
    items = summ.get("items_shown", {})
    if regret:
        typer.echo("\nregret on the post-teaching tests (mean [95% CI]; items shown: mean/max)")
        for model, per_dom in regret.items():
            for dom, per_cond in per_dom.items():
                for cond, r in per_cond.items():
                    it = items.get(model, {}).get(dom, {}).get(cond, {})
                    typer.echo(f"  {model} {dom} {cond}: {r['mean']:.3f} "
                               f"[{r['ci_low']:.3f},{r['ci_high']:.3f}]"
                               + (f"  items {it['mean']:.1f}/{it['max']}" if it else ""))
    for h in summ["h1"]:
        if h["domain"] in ("all",) or len({x["domain"] for x in summ["h1"]}) == 1:
            rho = "n/a" if h["spearman_rho"] is None else f"{h['spearman_rho']:+.3f}"
            typer.echo(f"H1 [{h['learner_model']}, {h['source']}]: Spearman rho(overlap, "
                       f"correct) = {rho} over {h['n']} answers")
