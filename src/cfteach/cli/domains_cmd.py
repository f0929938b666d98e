"""`cfteach domains`: list the built-in domains, or check and summarise a domain file.

Heavy imports happen inside the command so `cfteach --help` stays fast.
"""

import json
from typing import Annotated, Any

import typer


def _summary(dom: Any) -> dict[str, Any]:
    from cfteach.domains.size import estimate_size

    est = estimate_size(dom)  # exact when cheap to count, else from a sample (no minute-long
    # enumeration of every instance of a big domain just to list it)
    return {
        "name": dom.name,
        "title": dom.title,
        "reference_name": dom.reference_name,
        "source": dom.source,
        "width": dom.width,
        "height": dom.height,
        "actions": list(dom.actions),
        "feature_names": list(dom.feature_names),
        "feature_labels": list(dom.feature_labels),
        "weights_raw": [float(x) for x in dom.weights_raw],
        "weights": [float(x) for x in dom.weights],
        "prior": dom.prior.tolist(),
        "posterior": dom.posterior.tolist(),
        "n_bits": dom.n_bits,
        "instances": est.instances,
        "demonstrations": est.demonstrations,
        "demonstrations_exact": est.exact,
    }


def register(app: typer.Typer) -> None:
    """Add `cfteach domains` to the app."""

    @app.command("domains")
    def domains_cmd(
        paths: Annotated[
            list[str] | None,
            typer.Argument(help="Domain names or TOML files (default: the built-in domains)."),
        ] = None,
        as_json: Annotated[
            bool, typer.Option("--json", help="Print a machine-readable JSON list.")
        ] = False,
    ) -> None:
        """List domains: features, weights, number of instances and of demonstrations."""
        from cfteach import domains
        from cfteach.cli._common import fail
        from cfteach.domains.check import errors_of, static_findings

        names = paths or domains.builtin_names()
        rows = []
        for name in names:
            try:
                dom = domains.load(name)
            except ValueError as exc:  # DomainFileError is a ValueError
                fail(str(exc))
            errors = errors_of(static_findings(dom))
            if errors:
                fail(errors[0].message + " (`cfteach check` runs every check)")
            rows.append(_summary(dom))
        if as_json:
            typer.echo(json.dumps(rows, indent=2))
            return
        header = ("domain", "features (raw weight)", "w* (unit norm)", "instances", "demos")
        table = [header] + [
            (
                r["name"],
                ", ".join(f"{f} {w:g}" for f, w in zip(r["feature_names"], r["weights_raw"],
                                                       strict=True)),
                "[" + ", ".join(f"{w:.3f}" for w in r["weights"]) + "]",
                str(r["instances"]),
                ("" if r["demonstrations_exact"] else "~") + str(r["demonstrations"]),
            )
            for r in rows
        ]
        widths = [max(len(row[i]) for row in table) for i in range(len(header))]
        for k, row in enumerate(table):
            cells = [c.ljust(w) if i < 3 else c.rjust(w)
                     for i, (c, w) in enumerate(zip(row, widths, strict=True))]
            typer.echo("  ".join(cells).rstrip())
            if k == 0:
                typer.echo("  ".join("-" * w for w in widths))
