"""`cfteach analyze`: the paper's statistics, figures and report from a study export.

One command, two sources: an export directory (`cfteach analyze EXPORT_DIR --out DIR`) or a
simulated study (`cfteach analyze --synthetic N --out DIR`, which first writes the simulated
export to DIR/export). Heavy imports happen inside the command so `cfteach --help` stays fast.
"""

from pathlib import Path
from typing import Annotated, NoReturn

import typer

from cfteach.cli import _options as _opt

_EXC = "Exclusions"
_SYN = "Synthetic data"


def _read_manual(path: Path) -> dict[str, str]:
    import pandas as pd

    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    if "participant_id" not in df.columns:
        raise ValueError(f"{path}: missing column 'participant_id'")
    reasons = df["reason"] if "reason" in df.columns else pd.Series(["manual"] * len(df))
    return {
        pid: (r or "manual exclusion") for pid, r in zip(df["participant_id"], reasons, strict=True)
    }


def _usage_error(message: str) -> NoReturn:
    """A one-line usage error (exit code 2), the same at any terminal width."""
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code=2)


def _is_own_code(filename: str) -> bool:
    """A frame of the installed package itself (decided by its directory, so a clone in a
    folder named ``cfteach`` does not make its tests look like the package's own code)."""
    import cfteach

    package = Path(cfteach.__file__).resolve().parent
    try:
        return Path(filename).resolve().is_relative_to(package)
    except (OSError, ValueError):
        return False


def unexpected_error(exc: BaseException, what: str) -> str:
    """One line for an error we did not foresee: what failed, where, and how to report it.

    The innermost frame of cfteach's own code and the file/column words of the message are
    what a user needs to find the bad input; the traceback itself stays out of the terminal.
    """
    import traceback

    frames = [f for f in traceback.extract_tb(exc.__traceback__) if _is_own_code(f.filename)]
    where = f" in {Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else ""
    msg = " ".join(str(exc).split()) or "(no message)"
    return f"{what} failed{where}: {type(exc).__name__}: {msg} (unexpected: please report it)"


def _padjust(name: str) -> str:
    """The correction's name as pingouin spells it (``bonferroni`` is ``bonf``); an unknown
    one is a usage error with a close match."""
    from cfteach.analysis.pipeline import PADJUST_METHODS
    from cfteach.cli._common import check_choice

    name = {"bonferroni": "bonf"}.get(name.lower(), name.lower())
    check_choice(name, PADJUST_METHODS, "--padjust")
    return name


def analyze(
    export_dir: Annotated[
        Path | None,
        typer.Argument(help="Directory with the study export CSVs (cfteach study export)."),
    ] = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Directory for the report.")] = Path(
        "analysis"
    ),
    padjust: Annotated[
        str,
        typer.Option(
            help="Correction of within-subjects post hocs and pairwise tests: "
            "holm, bonf (or bonferroni), sidak, fdr_bh, fdr_by, none."
        ),
    ] = "holm",
    no_figures: Annotated[bool, typer.Option("--no-figures", help="Skip the plots.")] = False,
    authors_tukey: Annotated[
        bool,
        typer.Option(
            "--authors-tukey/--no-authors-tukey",
            help="Also report the authors' between-groups Tukey for H1 (labelled; it ignores "
            "the pairing).",
        ),
    ] = True,
    aggregate_sd: Annotated[
        float,
        typer.Option(
            help="Outlier rule 1: proportion correct below mean - k SD (0 disables).",
            rich_help_panel=_EXC,
        ),
    ] = 3.0,
    aggregate_mad: Annotated[
        float | None,
        typer.Option(
            help="Robust outlier rule: proportion correct below median - k MAD (default: off).",
            rich_help_panel=_EXC,
        ),
    ] = None,
    item_sd: Annotated[
        float,
        typer.Option(
            help="Outlier rule 2: a reward below the item mean - k SD is low (0 disables).",
            rich_help_panel=_EXC,
        ),
    ] = 3.0,
    item_count_sd: Annotated[
        float,
        typer.Option(
            help="Outlier rule 2: flag more low rewards than mean + k SD of the counts.",
            rich_help_panel=_EXC,
        ),
    ] = 3.0,
    counts_among_all: Annotated[
        bool,
        typer.Option(
            "--counts-among-all",
            help="Rule 2: take count statistics over all "
            "participants (authors: only those with >= 1 low reward).",
            rich_help_panel=_EXC,
        ),
    ] = False,
    item_means_include_flagged: Annotated[
        bool,
        typer.Option(
            "--item-means-include-flagged",
            help="Rule 2: keep rule-1 outliers in the item means (authors: leave them out).",
            rich_help_panel=_EXC,
        ),
    ] = False,
    keep_preview: Annotated[
        bool,
        typer.Option("--keep-preview", help="Keep preview/test sessions.", rich_help_panel=_EXC),
    ] = False,
    expected_tests: Annotated[
        int | None,
        typer.Option(
            help="Tests a complete participant has (default: the most "
            "any completed participant has).",
            rich_help_panel=_EXC,
        ),
    ] = None,
    min_minutes: Annotated[
        float | None,
        typer.Option(
            help="Exclude sessions completed faster than this many minutes (default: off; "
            "shorter than 10 min is always flagged in the report).",
            rich_help_panel=_EXC,
        ),
    ] = None,
    exclude_file: Annotated[
        Path | None,
        typer.Option(
            help="CSV with participant_id (and optional reason) to exclude by hand.",
            rich_help_panel=_EXC,
            exists=True,
            dir_okay=False,
        ),
    ] = None,
    synthetic: Annotated[
        int | None,
        typer.Option(
            help="Simulate a study of N completed participants instead of reading EXPORT_DIR.",
            rich_help_panel=_SYN,
            min=1,
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the simulation.", rich_help_panel=_SYN)] = 0,
    difficulty_effect: Annotated[
        float,
        typer.Option(
            help="Scale of the planted difficulty effect (0 = none).", rich_help_panel=_SYN
        ),
    ] = 1.0,
    interaction: Annotated[
        float,
        typer.Option(
            help="Planted counterfactual x difficulty interaction (logit).", rich_help_panel=_SYN
        ),
    ] = 0.35,
    keep_session: Annotated[
        list[str] | None,
        typer.Option(
            "--keep-session",
            help="Of a Prolific participant with several sessions, the one (participant_id) "
            "to analyse; repeat for each such participant.",
            rich_help_panel=_EXC,
        ),
    ] = None,
    export_only: Annotated[
        bool,
        typer.Option(
            "--export-only",
            help="With --synthetic: write the export, skip the analysis.",
            rich_help_panel=_SYN,
        ),
    ] = False,
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """Run the paper's statistics on a study export (or a simulated one).

    Writes report.md, report.html, results.json and figures/ to --out; see docs/analysis.md.
    """
    if (export_dir is None) == (synthetic is None):
        _usage_error("give either EXPORT_DIR or --synthetic N (exactly one)")
    if export_only and synthetic is None:
        _usage_error("--export-only needs --synthetic")
    from cfteach.cli import _progress
    from cfteach.cli._common import check_out_dir

    _progress.set_quiet(quiet)
    padjust = _padjust(padjust)
    check_out_dir(out)  # before the work
    import click  # here, not at the top: `cfteach --help` stays fast

    from cfteach.analysis import (
        AnalysisConfig,
        ExclusionConfig,
        ExportError,
        SyntheticConfig,
        generate,
        write_export,
    )
    from cfteach.analysis import analyze as run

    note = None
    try:
        if synthetic is not None:
            scfg = SyntheticConfig(
                n_participants=synthetic,
                seed=seed,
                difficulty_effect=difficulty_effect,
                interaction=interaction,
            )
            export_dir = write_export(generate(scfg), out / "export")
            note = (
                f"**Simulated data**: `cfteach analyze --synthetic {synthetic} --seed {seed} "
                f"--difficulty-effect {difficulty_effect:g} --interaction {interaction:g}` "
                "(planted effects; see docs/analysis.md). Not the paper's data."
            )
            typer.echo(
                f"wrote simulated export ({synthetic} participants, seed {seed}) to {export_dir}"
            )
            if export_only:
                return
        excl = ExclusionConfig(
            drop_preview=not keep_preview,
            expected_tests=expected_tests,
            aggregate_sd=aggregate_sd or None,
            aggregate_mad=aggregate_mad or None,
            item_sd=item_sd or None,
            item_count_sd=item_count_sd or None,
            item_counts_among_nonzero=not counts_among_all,
            item_means_exclude_flagged=not item_means_include_flagged,
            manual=_read_manual(exclude_file) if exclude_file else {},
            min_minutes=min_minutes,
        )
        cfg = AnalysisConfig(
            exclusions=excl,
            padjust=padjust,
            figures=not no_figures,
            authors_tukey=authors_tukey,
            keep_sessions=tuple(keep_session or ()),
        )
        assert export_dir is not None  # exactly one of EXPORT_DIR and --synthetic (above)
        with _progress.busy("analysing"):
            results = run(export_dir, out, cfg, note=note)
    except (typer.Exit, click.ClickException):
        raise
    except (ExportError, ValueError) as exc:
        typer.echo("Error: " + " ".join(str(exc).split()), err=True)
        raise typer.Exit(code=2) from exc
    except Exception as exc:  # noqa: BLE001 - no traceback may reach the user (see docs)
        typer.echo(f"Error: {unexpected_error(exc, f'analysis of {export_dir}')}", err=True)
        raise typer.Exit(code=1) from exc
    p = results["participants"]
    if "paper_analysis" in results:  # closed_loop sessions only
        typer.echo(f"{p['n_sessions']} session(s): {results['paper_analysis']['skipped']}.")
        typer.echo(f"report: {out / 'report.html'}  ({out / 'report.md'}, {out / 'results.json'})")
        return
    rm = results["h1"]["rm_anova"]
    from cfteach.analysis.report_format import fmt_F

    h1 = (
        f"not computed ({rm['skipped']})"
        if "skipped" in rm
        else fmt_F(rm["df1"], rm["df2"], rm["F"], rm["p"])
    )
    closed = p.get("n_closed_loop", 0)
    also = f"; {closed} closed_loop in their own section" if closed else ""
    typer.echo(
        f"{p['n_retained']} of {p['n_sessions']} sessions analysed ({p['n_excluded']} "
        f"excluded{also}). H1: {h1}."
    )
    from cfteach.analysis.pipeline import skipped_steps

    if failed := skipped_steps(results):
        typer.echo(f"Warning: not computed (error; see report.md): {', '.join(failed)}", err=True)
    typer.echo(f"report: {out / 'report.html'}  ({out / 'report.md'}, {out / 'results.json'})")


def power(
    n: Annotated[
        list[str] | None,
        typer.Option("--n", help="Numbers of participants to simulate (repeat the option "
                     "or comma-separate)."),
    ] = None,
    sims: Annotated[int, typer.Option(help="Simulated studies per N.", min=1)] = 100,
    seed: Annotated[int, typer.Option(help="Seed of the first simulated study.")] = 0,
    alpha: Annotated[float, typer.Option(help="Significance level.", min=0.0, max=1.0)] = 0.05,
    out: Annotated[Path, typer.Option("--out", "-o", help="Directory for the table and plot.")] = (
        Path("power")
    ),
    difficulty_effect: Annotated[
        float, typer.Option(help="Scale of the paper's difficulty effect.", rich_help_panel=_SYN)
    ] = 1.0,
    interaction: Annotated[
        float,
        typer.Option(help="Counterfactual x difficulty (logit).", rich_help_panel=_SYN),
    ] = 0.35,
    feature_effect: Annotated[
        float, typer.Option(help="Feature scaffolding main effect (logit).", rich_help_panel=_SYN)
    ] = 0.0,
    cf_fs_interaction: Annotated[
        float,
        typer.Option(help="Counterfactual x feature crossover (logit).", rich_help_panel=_SYN),
    ] = 0.0,
    proposed_interaction: Annotated[
        float,
        typer.Option(
            help="Difficulty effect of the proposed condition only (logit; a three-way effect).",
            rich_help_panel=_SYN,
        ),
    ] = 0.0,
    quiet: Annotated[bool, _opt.quiet()] = False,
) -> None:
    """Power vs N for each hypothesis, by simulating the design at planted effect sizes.

    Defaults plant the paper's reported difficulty means and the synthetic generator's
    counterfactual x difficulty interaction; writes power.md, power.csv and power.png/.svg.
    """
    from cfteach.analysis.power import MIN_PARTICIPANTS, power_curve, write_power_report
    from cfteach.cli import _progress
    from cfteach.cli._common import check_out_dir

    _progress.set_quiet(quiet)
    check_out_dir(out)  # before the simulations
    from cfteach.cli._lists import split_list

    try:
        ns = sorted({int(x) for x in split_list(n) or ["24", "48", "96", "144", "216"]})
    except ValueError:
        _usage_error(f"--n takes whole numbers of participants, got {', '.join(n or [])}")
    if ns[0] < MIN_PARTICIPANTS:
        _usage_error(
            f"--n must be at least {MIN_PARTICIPANTS} (two participants per condition), got {ns[0]}"
        )
    effects = {
        "difficulty_effect": difficulty_effect,
        "interaction": interaction,
        "feature_effect": feature_effect,
        "cf_fs_interaction": cf_fs_interaction,
        "proposed_interaction": proposed_interaction,
    }
    try:
        table = power_curve(ns, sims, effects, seed=seed, alpha=alpha,
                            progress=_progress.enabled())
        paths = write_power_report(table, out, alpha)
    except Exception as exc:  # noqa: BLE001 - no traceback may reach the user
        typer.echo(f"Error: {unexpected_error(exc, 'power simulation')}", err=True)
        raise typer.Exit(code=1) from exc
    typer.echo(Path(paths["md"]).read_text(encoding="utf-8").rstrip())
    typer.echo(f"wrote {paths['md']}, {paths['csv']}, {paths['png']}")


def register(app: typer.Typer) -> None:
    """Add `cfteach analyze` and `cfteach power` to the app."""
    app.command("analyze")(analyze)
    app.command("power")(power)
