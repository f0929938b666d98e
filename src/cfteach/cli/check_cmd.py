"""`cfteach check DOMAIN...`: every check a domain must pass, and its size and cost, before
anything is taught (docs/domains.md, "Checks before planning")."""

from __future__ import annotations

from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    """Add `cfteach check` to the app."""

    @app.command("check")
    def check_cmd(
        names: Annotated[list[str], typer.Argument(
            help="Domain names, TOML files or random:WxH:fF:nN:sS specs.")],
        force: Annotated[bool, typer.Option(
            "--force", help="Run the planning checks even when the domain looks too big "
                            "for the free memory.")] = False,
    ) -> None:
        """Check domains before teaching, and estimate what teaching them costs.

        Checks: at least 3 features, w* inside the file's prior and posterior, every
        instance's goal reachable from its start and from every state, no reward loop that
        w* pays for. Prints instances, states, demonstrations and the estimated time and
        peak memory of `cfteach teach`. Exits 1 if a domain has an error."""
        from cfteach import domains
        from cfteach.cli._common import fail
        from cfteach.domains.check import check_domain, errors_of, static_findings
        from cfteach.domains.size import (
            available_memory,
            estimate_size,
            human_bytes,
            shrink_advice,
        )

        bad = 0
        for name in names:
            try:
                dom = domains.load(name)
            except ValueError as exc:
                fail(str(exc))
            typer.echo(f"{dom.name} ({dom.source})")
            found = static_findings(dom)
            est = estimate_size(dom)
            for line in est.lines():
                typer.echo(f"  {line}")
            free = available_memory()
            if free is not None:
                typer.echo(f"  free memory: {human_bytes(free)}")
            partial = False
            if not errors_of(found):
                if free is not None and est.teach_peak_bytes > free and not force:
                    typer.echo(f"  warning: teaching needs more memory than is free: "
                               f"{shrink_advice(dom, est)}")
                    typer.echo("  planning checks skipped (they would compile the domain; "
                               "--force runs them anyway)")
                    partial = True
                else:
                    found = check_domain(dom)
            errors = errors_of(found)
            for f in found:
                typer.echo(f"  {f}", err=f.level == "error")
            if errors:
                bad += 1
                typer.echo(f"Error: {dom.name}: {len(errors)} error(s); see above", err=True)
            else:
                typer.echo("  ok (file checks only)" if partial else "  ok")
        if bad:
            raise typer.Exit(1)
