"""Regenerate every picture in docs/images, and the README's table of the report's numbers,
from the current code, in one run (so pictures and numbers always agree).

    .venv/bin/python scripts/docs_images.py [--only report|sphere|study|closed-loop]

Steps: `cfteach reproduce` (profile default, seed 0) into a temporary folder; the report's
first screen and the delivery curricula, photographed in headless Chromium (1280 x 800);
a belief sphere (`cfteach render belief delivery/proposed.json --demo 1`); the study pages
(`cfteach study init --from` that output, then the study's own screenshot walk; and a
`--preview` skateboard study with the closed_loop condition for its three kinds of item); the
README's numbers between its `report-numbers` markers (tests/test_readme_numbers.py checks
them against a fresh run); the closed-loop teacher's particle beliefs
(scripts/closed-loop-figures.py, which can also draw them alone into any folder).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
IMAGES = ROOT / "docs" / "images"
README = ROOT / "README.md"

STUDY_PAGES = ("practice", "domain_intro", "demos", "test")
STUDY_IMAGES = {"study-practice.png", "study-domain-intro.png", "study-demos-delivery.png",
                "study-demos-skateboard.png", "study-test-delivery.png",
                "study-test-skateboard.png", "study-test-tiles.png"}
CONDITIONS = ("baseline", "feature_only", "counterfactual_only", "proposed")


def run(*args: str) -> None:
    print("$ cfteach", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-c", "from cfteach.cli import main; main()", *args],
                   check=True, cwd=ROOT)


def report_shots(index: Path) -> None:
    from playwright.sync_api import sync_playwright

    from cfteach.study.screenshots import ARGS, CHROMIUM

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(index.as_uri())
        page.wait_for_load_state("load")
        page.screenshot(path=str(IMAGES / "report-first-screen.png"))
        page.goto(index.as_uri() + "#delivery")
        page.wait_for_timeout(300)
        page.screenshot(path=str(IMAGES / "report-curricula.png"))
        browser.close()
    print("wrote report-first-screen.png, report-curricula.png")


def study_shots(results: Path, tmp: Path) -> None:
    from cfteach.study.screenshots import take_screenshots

    study = tmp / "study"
    run("study", "init", "--out", str(study), "--from", str(results))
    shots = tmp / "shots"
    saved = take_screenshots(study, shots, prefix="study-", kinds=STUDY_PAGES)
    kept = [p for p in saved if p.name in STUDY_IMAGES]  # the pages the docs show
    for p in kept:
        p.replace(IMAGES / p.name)
    print("wrote", ", ".join(p.name for p in kept))


CLOSED_LOOP_IMAGES = {"study-closed-loop-demonstration.png", "study-closed-loop-test.png",
                      "study-closed-loop-feedback.png"}


def closed_loop_study_shots(tmp: Path) -> None:
    """The live closed_loop condition's pages: a lesson, a diagnostic test, feedback."""
    from cfteach.study.screenshots import take_screenshots

    study = tmp / "cl-study"
    run("study", "init", "--out", str(study), "--preview", "--domain", "skateboard",
        "--condition", "closed_loop", "--teacher", "max_items=9", "--demo-step-ms", "200")
    saved = take_screenshots(study, tmp / "cl-shots", prefix="study-", kinds=("closed_loop",))
    kept = [p for p in saved if p.name in CLOSED_LOOP_IMAGES]
    for p in kept:
        p.replace(IMAGES / p.name)
    print("wrote", ", ".join(p.name for p in kept))


def numbers_table(results: Path) -> str:
    """The README's block: per domain and condition, demonstrations and final belief area."""
    lines = ["| domain | " + " | ".join(CONDITIONS) + " |",
             "|---|" + "---|" * len(CONDITIONS)]
    for name in ("delivery", "tiles", "skateboard"):
        cells = []
        for cond in CONDITIONS:
            cur = json.loads((results / name / f"{cond}.json").read_text())
            cells.append(f"{len(cur['demos'])} demos, {cur['final_belief']['area']:.4g} sr")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_readme_numbers(results: Path) -> None:
    text = README.read_text()
    block = re.compile(r"(<!-- report-numbers[^\n]*-->\n)(.*?)(<!-- /report-numbers -->)", re.S)
    if not block.search(text):
        raise SystemExit("README.md lost its <!-- report-numbers --> markers")
    README.write_text(block.sub(lambda m: m.group(1) + numbers_table(results) + "\n"
                                + m.group(3), text))
    print("updated README.md's report numbers")


def closed_loop_shots() -> None:
    import runpy

    drawn = runpy.run_path(str(ROOT / "scripts" / "closed-loop-figures.py"))["main"](IMAGES)
    print("wrote", drawn.name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("report", "sphere", "study", "closed-loop"))
    args = parser.parse_args()
    IMAGES.mkdir(parents=True, exist_ok=True)
    if args.only in (None, "closed-loop"):
        closed_loop_shots()
    if args.only == "closed-loop":
        return
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        results = tmp / "reproduce"
        run("reproduce", "--out", str(results), "--profile", "default", "--seed", "0")
        if args.only in (None, "report"):
            report_shots(results / "index.html")
            write_readme_numbers(results)
        if args.only in (None, "sphere"):
            run("render", "belief", str(results / "delivery" / "proposed.json"), "--demo", "1",
                "--out", str(IMAGES / "belief-sphere.png"))
        if args.only in (None, "study"):
            study_shots(results, tmp)
            closed_loop_study_shots(tmp)


if __name__ == "__main__":
    main()
