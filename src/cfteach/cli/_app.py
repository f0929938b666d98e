"""The `cfteach` Typer app: one module per command family, each with `register(app)`.

Imported only when a command runs or help is shown (`cfteach.cli.app`); `cfteach --version`
answers without it."""

from __future__ import annotations

import importlib
import os
import sys

import typer
from typer.core import TyperGroup
from typer.models import CommandInfo, TyperInfo

from cfteach.cli._aliases import rewrite


class _Group(TyperGroup):
    """The root command: old option spellings become the current ones (docs/cli.md)."""

    def main(self, args=None, *a, **kw):  # noqa: ANN001, ANN002, ANN003, ANN201
        return super().main(rewrite(sys.argv[1:] if args is None else args), *a, **kw)


def _no_broken_words() -> None:
    """Help text wraps between words only: click's wrapper would cut a long word (a URL
    default such as .../submissions/complete?cc=) in two at a narrow terminal."""
    import importlib
    import textwrap

    for name in ("typer._click._textwrap", "click._textwrap"):  # typer's own copy, or click
        if name.split(".")[0] not in sys.modules and name.startswith("click"):
            continue  # Typer does not use click itself: nothing to patch, nothing to import
        try:
            module = importlib.import_module(name)
        except ImportError:
            continue
        base = module.TextWrapper
        if getattr(base, "_cfteach_whole_words", False):
            continue

        # a subclass of whichever TextWrapper was found at run time, which mypy cannot type
        class _WholeWords(base):  # type: ignore[misc, valid-type]
            _cfteach_whole_words = True
            # click's own version always cuts; the standard library's honours the flag
            _handle_long_word = textwrap.TextWrapper._handle_long_word

            def __init__(self, *args, **kw) -> None:  # noqa: ANN002, ANN003
                kw.update(break_long_words=False, break_on_hyphens=False)
                super().__init__(*args, **kw)

        setattr(module, "TextWrapper", _WholeWords)  # noqa: B010 (mypy: not a declared attribute)


_no_broken_words()

app = typer.Typer(
    cls=_Group,
    name="cfteach",
    help="Counterfactual-aware teaching of a robot's reward through demonstrations.",
    no_args_is_help=True,
    add_completion=False,
    # Plain click help: wraps at word boundaries and never cuts an option name short.
    rich_markup_mode=None,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

# Each module owns one family of commands; registering them here keeps this file stable.
_COMMAND_MODULES = (
    "check_cmd",
    "domains_cmd",
    "teach_cmd",
    "render_cmd",
    "reproduce_cmd",
    "simulate_cmd",
    "study_cmd",
    "analyze_cmd",
    "export_cmd",
)


def _print_version(value: bool) -> None:
    if value:
        from cfteach import __version__

        typer.echo(f"cfteach {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True,
                                 help="Print cfteach's version and exit."),
) -> None:
    """Counterfactual-aware teaching of a robot's reward through demonstrations."""


@app.command()
def version() -> None:
    """Print cfteach's version."""
    from cfteach import __version__

    typer.echo(__version__)


for _name in _COMMAND_MODULES:
    importlib.import_module(f"cfteach.cli.{_name}").register(app)


def _first_sentence(text: str | None) -> str | None:
    """A command's summary for the command list: its first sentence, whole (click would cut
    a long one at the terminal's width with "...")."""
    if not text:
        return None
    para = " ".join(text.strip().split("\n\n")[0].split())
    end = para.find(". ")
    return para if end < 0 else para[: end + 1]


def _whole_summaries(typer_app: typer.Typer) -> None:
    """Give every command and group, at every level, its whole first sentence as summary."""
    infos: list[CommandInfo | TyperInfo] = [
        *typer_app.registered_commands,
        *typer_app.registered_groups,
    ]
    for info in infos:
        cb = getattr(info, "callback", None)
        sub = getattr(info, "typer_instance", None)
        if not info.short_help:
            info.short_help = _first_sentence(
                info.help or (sub.info.help if sub is not None else None)
                or (cb.__doc__ if cb else None))
        if sub is not None:
            _whole_summaries(sub)


_whole_summaries(app)


def main() -> None:
    """Entry point of the `cfteach` console script: no traceback reaches the user (set
    CFTEACH_DEBUG=1 to see one)."""
    try:
        app()
    except KeyboardInterrupt:
        typer.echo("Error: interrupted", err=True)
        sys.exit(130)
    except Exception as exc:  # noqa: BLE001 - the last line of defence
        if os.environ.get("CFTEACH_DEBUG"):
            raise
        typer.echo(f"Error: {type(exc).__name__}: {exc} (an unexpected failure; set "
                   "CFTEACH_DEBUG=1 to see the traceback and please report it)", err=True)
        sys.exit(1)
