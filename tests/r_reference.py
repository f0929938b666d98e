"""Run reference fits in R (lme4, blme, afex, ordinal) through `Rscript` for the tests.

`scripts/setup --system` installs them from Debian (r-base-core r-cran-lme4 r-cran-blme
r-cran-afex r-cran-ordinal). Where R or a package is missing the tests say so: they fail
when CI is set (as the PostgreSQL tests do) and are skipped, with the reason, otherwise.
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

PACKAGES = ("lme4", "blme", "afex", "ordinal")
APT = "r-base-core r-cran-lme4 r-cran-blme r-cran-afex r-cran-ordinal"


@functools.cache
def _missing() -> str | None:
    """Why R cannot be used (None when Rscript and every package load)."""
    exe = shutil.which("Rscript")
    if exe is None:
        return "Rscript not found"
    code = "; ".join(f"suppressMessages(library({p}))" for p in PACKAGES)
    try:
        res = subprocess.run([exe, "-e", code], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"Rscript does not run ({exc})"
    if res.returncode != 0:
        return "an R package is missing: " + " ".join(res.stderr.split())[:200]
    return None


def require_r() -> str:
    """Path of Rscript; fails in CI and skips elsewhere when R or a package is missing."""
    why = _missing()
    if why:
        msg = f"{why}: run `scripts/setup --system` (apt-get install {APT})"
        if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
            pytest.fail(msg + " so the R reference tests run in CI")
        pytest.skip(msg + " (outside CI)")
    return str(shutil.which("Rscript"))


def run_r(code: str, workdir: Path, timeout: float = 900) -> None:
    """Run an R script in `workdir` (it reads and writes CSVs there); fail with R's stderr."""
    exe = require_r()
    script = workdir / "reference.R"
    script.write_text(code, encoding="utf-8")
    res = subprocess.run(
        [exe, "--vanilla", str(script)], cwd=workdir, capture_output=True, text=True,
        timeout=timeout,
    )
    assert res.returncode == 0, f"R failed:\n{res.stderr[-3000:]}"


def read_r(path: Path) -> pd.DataFrame:
    """A CSV written by R's write.csv(row.names = FALSE)."""
    return pd.read_csv(path, keep_default_na=False, na_values=["NA"])


#: R code that reads an export's test responses for the retained participants
#: (retained.csv: participant_id) and codes them as cfteach.analysis.glmm does, with R's
#: own contrasts: cf, fs centred; difficulty contr.sum with medium last; domain contr.sum;
#: domain_position centred.
R_GLMM_DATA = r"""
suppressMessages({library(lme4)})
t <- read.csv("export/test_responses.csv", stringsAsFactors = FALSE)
keep <- read.csv("retained.csv", stringsAsFactors = FALSE)$participant_id
t <- t[t$participant_id %in% keep, ]
t$cf <- as.numeric(t$condition %in% c("counterfactual_only", "proposed")) - 0.5
t$fs <- as.numeric(t$condition %in% c("feature_only", "proposed")) - 0.5
t$difficulty <- factor(t$difficulty, levels = c("low", "high", "medium"))
contrasts(t$difficulty) <- contr.sum(3)
t$domain <- factor(t$domain, levels = sort(unique(t$domain)))
contrasts(t$domain) <- contr.sum(nlevels(t$domain))
t$pos <- t$domain_position - mean(t$domain_position)
t$pid <- factor(t$participant_id)
t$item <- factor(t$test_id)
form <- optimal ~ cf * fs * difficulty + domain + pos + (1 | pid) + (1 | item)
"""


def glmm_names(r_names: list[str], domains: list[str]) -> dict[str, str]:
    """R's coefficient names -> cfteach's term names."""
    parts = {
        "cf": "counterfactual",
        "fs": "feature_scaffolding",
        "difficulty1": "difficulty[low]",
        "difficulty2": "difficulty[high]",
        "pos": "domain_position",
        **{f"domain{i + 1}": f"domain[{d}]" for i, d in enumerate(domains[:-1])},
    }
    return {n: ":".join(parts[p] for p in n.split(":")) for n in r_names if n != "(Intercept)"}
