"""What a newcomer read wrong in the docs (issue 24, items 12 and 13): stale "next" and
"not yet" claims, a field shape that does not exist, a lexicographic subset check, a rule
`check` does not apply, a table split by a paragraph, a time without its machine, and the
2021 domain's number of demonstrations."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from cfteach import domains

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _read(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def test_architecture_no_longer_says_the_study_condition_comes_next() -> None:
    text = " ".join(_read("architecture.md").split())
    assert "next, study/" not in text and "the study app next" not in text
    assert "live in the study app" in text


def test_closed_loop_page_has_no_not_yet_heading_over_what_is_in() -> None:
    assert not re.search(r"^#+ Not yet\s*$", _read("closed-loop.md"), re.M)


def test_simulate_names_the_proportion_rows_fields_as_written() -> None:
    from cfteach.simulate import summary

    text = " ".join(_read("simulate.md").split())
    assert "difficulty: mean," not in text
    documented = re.search(r"a list of rows with (.*?)\)", text).group(1)
    fields = re.findall(r"`(\w+)`", documented)
    source = Path(summary.__file__).read_text(encoding="utf-8")
    assert fields and all(f'"{f}"' in source for f in fields), fields


def test_domains_page_checks_a_subset_as_a_set_and_lists_checks_rules() -> None:
    text = _read("domains.md")
    assert "lead's README" not in text
    assert '} <= {0, 16, 32, 48})' in text
    rules = text[text.index("| rule | why |"):]
    rules = rules[: rules.index("\n\n")]
    assert "exactly 3 features" not in rules
    assert "some optimal path reaches each instance's goal" in rules
    assert "half the free memory" in rules


def test_schemas_final_belief_row_sits_in_its_table() -> None:
    lines = _read("schemas.md").splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("| `final_belief` |"))
    assert lines[i - 1].startswith("| `demos` |")


def test_readme_states_the_machine_and_load_of_its_timing() -> None:
    text = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    assert "about 10 s" not in text
    assert re.search(r"2-core machine at a load average of [\d ]+to \d+", text)


def test_readme_gymnasium_form_works_in_a_fresh_interpreter() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    call = 'gymnasium.make("cfteach.gym:cfteach/Delivery-v0")'
    assert call in text
    code = f"import gymnasium\nenv = {call}\nprint(env.reset(seed=0)[0] is not None)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0 and res.stdout.strip() == "True", res.stderr


def test_the_2021_taxi_teaches_four_demonstrations() -> None:
    dom = domains.load(str(ROOT / "examples" / "domains" / "augmented_taxi_2021.toml"))
    assert dom.max_demos == 4
