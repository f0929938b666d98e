"""`cfteach render ...`: pictures of states, demonstrations and beliefs from the command line.

Heavy imports happen inside the commands so `cfteach --help` stays fast.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

render_app = typer.Typer(
    help="Draw grids, demonstrations and beliefs (SVG, PNG, GIF or text).",
    no_args_is_help=True,
)

_FORMATS = ("gif", "png", "svg", "txt")


def _fail(message: str) -> None:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(2)


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        _fail(f"{path}: {exc.strerror or exc}")
    except json.JSONDecodeError as exc:
        _fail(f"{path}: not valid JSON ({exc})")
    if not isinstance(data, dict) or "schema" not in data:
        _fail(f"{path}: expected a cfteach curriculum or tests JSON object with a 'schema' key")
    return data


@render_app.command("state")
def state_cmd(
    domain: Annotated[str, typer.Argument(help="Domain name or TOML file.")],
    env_code: Annotated[
        str, typer.Argument(help="Instance bits (e.g. 000010 for delivery) or its index.")
    ],
    state: Annotated[
        str | None,
        typer.Option(help="State as JSON, e.g. '{\"agent\": [2, 1], ...}'; default: initial."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help=".svg, .png or .txt; default: print text.")
    ] = None,
    cell_px: Annotated[int, typer.Option(help="Pixels per cell.")] = 48,
) -> None:
    """Draw one state of one instance."""
    from cfteach import domains, render

    try:
        dom = domains.load(domain)
        n_bits = dom.n_bits
        if len(env_code) == n_bits and set(env_code) <= {"0", "1"}:
            key: Any = tuple(int(c) for c in env_code)
        elif env_code.isdigit():
            key = int(env_code)
        else:
            raise ValueError(
                f"env code {env_code!r}: give {n_bits} bits (e.g. {'0' * n_bits}) "
                "or an instance index"
            )
        inst = dom.instance(key)
        st = inst.initial_state if state is None else inst.state_from_json(json.loads(state))
        if out is None:
            typer.echo(render.text_of(inst, st))
            typer.echo(render.legend(render.layout_from_instance(inst)))
            return
        render.save(inst, st, out, cell_px=cell_px)
    except (ValueError, KeyError, IndexError, FileNotFoundError) as exc:
        _fail(str(exc))
    typer.echo(f"Wrote {out}")


@render_app.command("demos")
def demos_cmd(
    file: Annotated[Path, typer.Argument(help="A curriculum or tests JSON file.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")] = Path("demos"),
    fmt: Annotated[str, typer.Option("--format", "-f", help="gif, png, svg or txt.")] = "gif",
    domain: Annotated[
        str | None, typer.Option(help="Domain name or TOML file; default: the file's domain.")
    ] = None,
    still: Annotated[
        str, typer.Option(help="Stills (png/svg/txt): 'last' (the end) or 'first' (the start).")
    ] = "last",
) -> None:
    """Draw every demonstration (or test) of a JSON file, one picture each."""
    from cfteach import domains, render

    if fmt not in _FORMATS:
        _fail(f"unknown format {fmt!r}; use one of {', '.join(_FORMATS)}")
    if still not in ("first", "last"):
        _fail(f"--still must be 'first' or 'last', got {still!r}")
    data = _read_json(file)
    if "demos" in data:
        items = [(f"demo{k}", d) for k, d in enumerate(data["demos"], start=1)]
    elif "tests" in data:
        items = [
            (f"{level}-{k}", t)
            for level, tests in data["tests"].items()
            for k, t in enumerate(tests, start=1)
        ]
    else:
        _fail(f"{file}: has neither 'demos' nor 'tests'")
    try:
        dom = domains.load(domain or data["domain"])
    except (ValueError, FileNotFoundError) as exc:
        _fail(str(exc))
    out.mkdir(parents=True, exist_ok=True)
    for name, demo in items:
        layout = render.layout_from_instance(dom.instance(int(demo["env_index"])))
        path = out / f"{name}.{fmt}"
        render.save_demo(layout, demo["states"], path, still=still)
    typer.echo(f"Wrote {len(items)} pictures to {out}")


@render_app.command("belief")
def belief_cmd(
    file: Annotated[Path, typer.Argument(help="A curriculum or tests JSON file.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="PNG (or SVG/PDF) file.")] = Path(
        "belief.png"
    ),
    demo: Annotated[
        int | None,
        typer.Option(help="Curriculum: also shade this demonstration's BEC (1-based)."),
    ] = None,
) -> None:
    """Draw a belief on the sphere: a curriculum's final belief or a test set's belief."""
    from cfteach.render import belief as bel

    data = _read_json(file)
    bec = None
    if "final_belief" in data:
        region = data["final_belief"]["constraints"]
        title = f"{data['domain']} {data['condition']}: final belief"
        if demo is not None:
            if not 1 <= demo <= len(data["demos"]):
                _fail(f"--demo {demo}: the curriculum has {len(data['demos'])} demonstrations")
            bec = data["demos"][demo - 1]["constraints"]
    elif "belief" in data:
        region = data["belief"]["constraints"]
        title = f"{data['domain']}: belief for testing"
    else:
        _fail(f"{file}: has neither 'final_belief' nor 'belief'")
    try:
        fig = bel.plot_belief_sphere(
            region,
            bec=bec,
            w_true=data["weights"],
            feature_names=data["feature_names"],
            title=title,
        )
    except ValueError as exc:
        _fail(str(exc))
    bel.save_figure(fig, out)
    typer.echo(f"Wrote {out}")


@render_app.command("report")
def report_cmd(
    out: Annotated[Path, typer.Argument(help="Directory with <domain>/*.json results.")],
) -> None:
    """Rebuild pictures and index.html from the JSON files in a results directory."""
    from cfteach.report import build_report, load_meta, load_results

    try:
        results = load_results(out)
    except (OSError, ValueError) as exc:
        _fail(str(exc))
    typer.echo(f"Report: {build_report(out, results, meta=load_meta(out))}")


def register(app: typer.Typer) -> None:
    """Add the `cfteach render` command group to the app."""
    app.add_typer(render_app, name="render")
