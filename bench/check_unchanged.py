"""Do the paper's curricula and tests stay the same? Run them into a folder, then diff two.

    .venv/bin/python bench/check_unchanged.py run /tmp/before     # on the old code
    .venv/bin/python bench/check_unchanged.py run /tmp/after      # on the new code
    .venv/bin/python bench/check_unchanged.py diff /tmp/before /tmp/after

`run` writes `cfteach reproduce --no-report` in both profiles (`default/`, `reference/`;
every curriculum and tests JSON of the three built-in domains) and `cfteach teach` of the 12
reference-profile curricula (3 domains x 4 conditions, `teach/`), timing each command.
`diff` compares every JSON file of the two folders, ignoring timing fields (`seconds`), and
exits 1 naming each file that differs or exists on one side only.
`run` takes extra options for `reproduce` after `--`, e.g. `-- --workers 1`.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

DOMAINS = ("delivery", "tiles", "skateboard")
CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")
TIMING_KEYS = {"seconds"}


def _cfteach(*args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from cfteach.cli import main; main()", *args],
                   check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def run(folder: Path, extra: list[str]) -> None:
    for profile in ("default", "reference"):
        s = _cfteach("reproduce", "--no-report", "--profile", profile, "--out",
                     str(folder / profile), *extra)
        print(f"reproduce --profile {profile} {' '.join(extra)}: {s:.1f} s", flush=True)
    total = 0.0
    for d in DOMAINS:
        for c in CONDITIONS:
            total += _cfteach("teach", d, "--condition", c, "--profile", "reference",
                              "--out", str(folder / "teach" / f"{d}-{c}.json"))
    print(f"12 reference curricula (cfteach teach): {total:.1f} s")


def _strip(data: Any) -> Any:
    if isinstance(data, dict):
        return {k: _strip(v) for k, v in data.items() if k not in TIMING_KEYS}
    if isinstance(data, list):
        return [_strip(v) for v in data]
    return data


def diff(a: Path, b: Path) -> int:
    left = {p.relative_to(a) for p in a.rglob("*.json")}
    right = {p.relative_to(b) for p in b.rglob("*.json")}
    bad = [f"only in {a}: {p}" for p in sorted(left - right)]
    bad += [f"only in {b}: {p}" for p in sorted(right - left)]
    for p in sorted(left & right):
        if _strip(json.loads((a / p).read_text())) != _strip(json.loads((b / p).read_text())):
            bad.append(f"differs: {p}")
    for line in bad:
        print(line)
    print(f"{len(left & right)} JSON files compared, {len(bad)} problems")
    return 1 if bad else 0


def main() -> None:
    args = sys.argv[1:]
    if len(args) >= 2 and args[0] == "run":
        extra = args[3:] if len(args) > 2 and args[2] == "--" else []
        run(Path(args[1]), extra)
    elif len(args) == 3 and args[0] == "diff":
        sys.exit(diff(Path(args[1]), Path(args[2])))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
