"""`cfteach check DOMAIN...`: every check a domain must pass, and its size and cost, before
anything is taught (docs/domains.md, "Checks before planning")."""

from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    """Add `cfteach check` to the app."""

    @app.command("check")
    def check_cmd(
        names: Annotated[list[str], typer.Argument(
            help="Domain names, TOML files or random:WxH:fF:nN:sS specs.")],
        force: Annotated[bool, typer.Option(
            "--force", help="Run the planning checks even when teaching the domain would need "
                            "more memory than is free.")] = False,
    ) -> None:
        """Check domains before teaching, and estimate what teaching them costs.

        Checks: at least 3 features, w* inside the file's prior and posterior, no reward
        loop that w* pays for, every instance's goal reachable from its start and from every
        state, and (a warning) some optimal path reaching the goal. Prints the checks run,
        instances, states, demonstrations and the estimated time and peak memory of
        `cfteach teach`: a warning above half the free memory, an error above it (--force
        checks anyway). Exits 1 if a domain has an error."""
        from cfteach import domains
        from cfteach.bec.demos import demo_set
        from cfteach.bec.ties import tie_findings
        from cfteach.cli._common import fail
        from cfteach.domains.check import CHECKS, errors_of, static_findings
        from cfteach.domains.size import (
            available_memory,
            estimate_size,
            human_bytes,
            shrink_advice,
        )
        from cfteach.mdp.soundness import check_domain

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
            planned = False
            too_big = free is not None and est.teach_peak_bytes > free
            if free is not None and free / 2 < est.teach_peak_bytes <= free:
                typer.echo(f"  warning: teaching needs about {human_bytes(est.teach_peak_bytes)}"
                           f", more than half of the free memory: {shrink_advice(dom, est)}")
            if free is not None and too_big and not force:
                typer.echo(f"  error: teaching needs about {human_bytes(est.teach_peak_bytes)}"
                           f" of memory, {human_bytes(free)} is free: "
                           f"{shrink_advice(dom, est)}; or pass --force (planning checks "
                           "skipped: they would compile the domain)", err=True)
                bad += 1
            elif not errors_of(found):
                found = check_domain(dom)
                planned = True
                if not errors_of(found):
                    found += tie_findings(demo_set(dom))
            errors = errors_of(found)
            for f in found:
                typer.echo(f"  {f}", err=f.level == "error")
            typer.echo("  checks run:" + ("" if planned else " (not the planning checks)"))
            for code, text, plan in CHECKS:
                if plan and not planned:
                    continue
                levels = {f.level for f in found if f.code.startswith(code)}
                verdict = ("FAILED" if "error" in levels else "warning" if levels else "passed")
                typer.echo(f"    {verdict}: {text}")
            if errors:
                bad += 1
                typer.echo(f"Error: {dom.name}: {len(errors)} error(s); see above", err=True)
            elif not (too_big and not force):
                warned = sum(f.level == "warning" for f in found)
                typer.echo(f"  ok ({warned} warning(s))" if warned else "  ok")
        if bad:
            raise typer.Exit(1)
