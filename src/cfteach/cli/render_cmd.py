"""`cfteach render ...`: pictures of states, demonstrations and beliefs from the command line.

Heavy imports happen inside the commands so `cfteach --help` stays fast.
"""

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from cfteach.cli._common import check_out_dir, check_out_file, fail

render_app = typer.Typer(
    help="Draw grids, demonstrations and beliefs (SVG, PNG, GIF or text).",
    no_args_is_help=True,
)

_FORMATS = ("gif", "png", "svg", "txt")


def _fail(message: str) -> None:
    fail(message)


def _instance_key(dom: Any, env_code: str) -> Any:
    """Bits (exactly the domain's number) or an index; a bit string of the wrong length is
    named as such rather than read as a large index."""
    n_bits, n = dom.n_bits, 2 ** dom.n_bits
    if len(env_code) == n_bits and set(env_code) <= {"0", "1"}:
        return tuple(int(c) for c in env_code)
    if set(env_code) <= {"0", "1"} and len(env_code) > 1 and (
            env_code.startswith("0") or int(env_code) >= n):
        raise ValueError(f"env code {env_code!r} has {len(env_code)} bits; {dom.name} "
                         f"instances have {n_bits} (e.g. {'0' * n_bits}), or give an "
                         f"index 0..{n - 1}")
    if env_code.isdigit():
        return int(env_code)
    raise ValueError(f"env code {env_code!r}: give {n_bits} bits (e.g. {'0' * n_bits}) "
                     f"or an instance index 0..{n - 1}")


def _parse_state(inst: Any, text: str) -> Any:
    example = json.dumps(inst.state_to_json(inst.initial_state))
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"--state {text!r} is not JSON ({exc.msg}); expected an object "
                         f"like {example}") from None
    return inst.state_from_json(data)


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

    check_out_file(out)
    if out is not None and out.suffix.lower() not in (".svg", ".png", ".txt"):
        _fail(f"--out {out}: give a .svg, .png or .txt file name")
    if cell_px < 1:
        _fail(f"--cell-px must be at least 1, got {cell_px}")
    try:
        dom = domains.load(domain)
        inst = dom.instance(_instance_key(dom, env_code))
        st = inst.initial_state if state is None else _parse_state(inst, state)
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
    check_out_dir(out)
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
    except (ValueError, FileNotFoundError, KeyError) as exc:
        _fail(str(exc))
    if data.get("domain") not in (None, dom.name):
        _fail(f"{file} holds {data['domain']!r} demonstrations but --domain {domain} is "
              f"{dom.name!r}; give the domain (or file) the JSON was made with")
    out.mkdir(parents=True, exist_ok=True)
    for name, demo in items:
        try:
            inst = dom.instance(int(demo["env_index"]))
            for st in demo["states"]:  # a JSON made for another domain fails here
                inst.state_from_json(st)
        except (ValueError, KeyError, IndexError, TypeError) as exc:
            _fail(f"{file}: {name}: does not fit domain {dom.name!r} ({exc})")
        layout = render.layout_from_instance(inst)
        path = out / f"{name}.{fmt}"
        try:
            render.save_demo(layout, demo["states"], path, still=still,
                             actions=demo.get("actions", ()), action_specs=dom.action_specs)
        except ValueError as exc:
            _fail(f"{file}: {name}: {exc}")
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

    check_out_file(out)
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
        from cfteach.report.build import feature_labels

        fig = bel.plot_belief_sphere(
            region,
            bec=bec,
            w_true=data["weights"],
            feature_names=feature_labels(str(data["domain"]), data["feature_names"]),
            title=title,
        )
    except (ValueError, KeyError, TypeError) as exc:
        _fail(str(exc))
    bel.save_figure(fig, out)
    typer.echo(f"Wrote {out}")


@render_app.command("report")
def report_cmd(
    out: Annotated[Path, typer.Argument(help="Directory with <domain>/*.json results.")],
) -> None:
    """Rebuild pictures and index.html from the JSON files in a results directory."""
    from cfteach.report import build_report, load_meta, load_results

    check_out_dir(out, "OUT")  # the report is written there: writable before any work
    try:
        results = load_results(out)
    except (OSError, ValueError) as exc:
        _fail(str(exc))
    typer.echo(f"Report: {build_report(out, results, meta=load_meta(out))}")


def register(app: typer.Typer) -> None:
    """Add the `cfteach render` command group to the app."""
    app.add_typer(render_app, name="render")
