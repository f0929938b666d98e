"""Progress bars on long steps (on a terminal, not under --quiet) and a command line that
answers --version without importing Typer or any heavy library."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cfteach.cli import _progress, app
from cli_runner import WideRunner

HEAVY = ("typer", "click", "numpy", "pandas", "sklearn", "matplotlib", "fastapi", "scipy")


def test_progress_shows_on_a_terminal_unless_quiet(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: True)
    _progress.set_quiet(False)
    assert _progress.enabled() and not _progress.bar(total=3).disable
    _progress.set_quiet(True)
    assert not _progress.enabled() and _progress.bar(total=3).disable
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: False)
    _progress.set_quiet(False)
    assert not _progress.enabled()


@pytest.mark.parametrize(("extra", "expected"), [([], True), (["--quiet"], False),
                                                 (["-q"], False)])
def test_power_and_simulate_pass_the_progress_choice_on(
        monkeypatch: pytest.MonkeyPatch, tmp_path, extra: list[str], expected: bool) -> None:
    seen: dict[str, bool] = {}

    def stop(name: str):  # noqa: ANN202
        def f(*_a, progress=None, **_k):  # noqa: ANN002, ANN003, ANN202
            seen[name] = progress
            raise ValueError("stop here")
        return f

    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: True)
    monkeypatch.setattr("cfteach.analysis.power.power_curve", stop("power"))
    monkeypatch.setattr("cfteach.simulate.sweep.run_sweep", stop("simulate"))
    WideRunner().invoke(app, ["power", "--n", "24", "--sims", "1", "--out",
                              str(tmp_path / "p"), *extra])
    WideRunner().invoke(app, ["simulate", "--domain", "skateboard", "--out",
                              str(tmp_path / "s"), *extra])
    assert seen == {"power": expected, "simulate": expected}


def _modules_after(args: list[str]) -> set[str]:
    code = ("import sys\nfrom cfteach.cli import main\n"
            f"sys.argv = ['cfteach', *{args!r}]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print('MODULES', *sorted({m.split('.')[0] for m in sys.modules}))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("MODULES"))
    return set(line.split()[1:])


def test_version_imports_nothing_heavy() -> None:
    assert _modules_after(["--version"]) & set(HEAVY) == set()


def test_help_imports_no_scientific_or_web_library() -> None:
    loaded = _modules_after(["--help"])
    assert "typer" in loaded  # help is Typer's
    assert loaded & {"numpy", "pandas", "sklearn", "matplotlib", "fastapi", "scipy"} == set()
