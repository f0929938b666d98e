"""Peak memory of one `cfteach teach` run on a subset of a domain's environments against
the whole domain: memory must grow with the work (issue 16, item 4).

    .venv/bin/python bench/bench_teach_memory.py [--domain FILE] [--conditions C,...]
                                                 [--envs SEL ...]

Default: bench/domains/taxi256.toml (256 instances), conditions baseline and proposed,
selections `0::16` (16 environments), `:16` and all 256. Each run is a fresh process running
the CLI in process; peak = its ru_maxrss. Also prints the peak of the same process after
only importing what `teach` imports (the fixed cost).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent

_CHILD = """
import json, resource, sys, time
args = json.loads(sys.argv[1])
t = time.perf_counter()
if args:
    from cfteach.cli import app
    try:
        app(args, standalone_mode=False)
    except SystemExit:
        pass
else:
    import cfteach.cli, cfteach.teaching, cfteach.teaching.baseline, sklearn.cluster  # noqa
print(json.dumps({"seconds": time.perf_counter() - t,
                  "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run(args: list[str]) -> dict:
    out = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(args)], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", default=str(HERE / "domains" / "taxi256.toml"))
    ap.add_argument("--conditions", default="baseline,proposed")
    ap.add_argument("--envs", nargs="*", default=["0::16", ":16", "all"])
    a = ap.parse_args()
    base = run([])
    print(f"imports only (cli, teaching, sklearn): peak {base['peak_mib']:.0f} MiB")
    print(f"{'condition':<20} {'envs':<8} {'peak MiB':>9} {'seconds':>8}")
    for cond in a.conditions.split(","):
        for sel in a.envs:
            args = ["teach", a.domain, "--condition", cond, "--out", "/dev/null"]
            if sel != "all":
                args += ["--envs", sel]
            r = run(args)
            print(f"{cond:<20} {sel:<8} {r['peak_mib']:>9.0f} {r['seconds']:>8.1f}", flush=True)


if __name__ == "__main__":
    main()
