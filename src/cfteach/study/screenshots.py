"""`cfteach study screenshots`: a PNG of each kind of page, as participants see it.

Useful for checking a study before launch (and for ethics-board submissions). Drives
Debian's Chromium through Playwright against a throw-away server and database.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import httpx

from .bot import find_test, run_participant
from .config import load_study
from .games import best_path, shortest_path
from .livesrv import running
from .server import create_app

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run",
        "--disable-dev-shm-usage"]
KINDS = ("consent", "practice", "domain_intro", "demos", "closed_loop", "survey", "test",
         "feedback", "demographics", "complete")
KEYS = {"up": "ArrowUp", "down": "ArrowDown", "left": "ArrowLeft", "right": "ArrowRight",
        "pickup": "p", "dropoff": "d"}


def take_screenshots(study_dir: str | Path, out: str | Path, *, prefix: str = "study-",
                     kinds: tuple[str, ...] = KINDS, chromium: str = CHROMIUM,
                     width: int = 1100, height: int = 900) -> list[Path]:
    """Walk one preview participant through the study, saving `<prefix><kind>.png`."""
    from playwright.sync_api import sync_playwright

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    study = load_study(study_dir)
    saved: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        # a private server for one walker, which polls the page state: no per-session limit
        app = create_app(study_dir, f"sqlite:///{Path(tmp) / 'shots.db'}", seed=0,
                         states_per_minute=0)
        with running(app) as base, sync_playwright() as p, httpx.Client(base_url=base) as c:
            browser = p.chromium.launch(executable_path=chromium, args=ARGS, headless=True)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(f"{base}/?mode=preview")
            page.wait_for_selector("main[data-step]")
            token = page.evaluate("sessionStorage.getItem('cfteach-token')")
            headers = {"X-Session-Token": token}
            seen: set[str] = set()
            while True:
                # wait (up to 5 s a read) while a closed-loop item is being decided
                st = c.get("/api/state", headers=headers, params={"wait": 5}).json()
                if st["step"].get("preparing"):
                    continue
                kind = st["step"]["kind"]
                name = kind.replace("_", "-")
                if kind in ("demos", "test"):  # one per domain: each has its own look
                    name += f"-{st['step']['domain']}"
                elif kind == "closed_loop":  # one per kind of item: demonstration, test...
                    name += f"-{st['step']['item']['kind']}"
                if kind in kinds and name not in seen:
                    seen.add(name)
                    page.reload()
                    page.wait_for_selector(f"main[data-step='{kind}']")
                    _stage(page, st, study)
                    path = out / f"{prefix}{name}.png"
                    page.screenshot(path=str(path), full_page=True)
                    saved.append(path)
                    if kind == "closed_loop" and st["step"]["item"]["kind"] == "demonstration":
                        # let the page's own play end first, or it would overlap the bot's
                        page.wait_for_selector("#board[data-watched='true']")
                    if kind == "demos":  # let the page's replay end before the bot plays
                        _wait_watched(c, headers, st["step"])
                if kind in ("complete", "screened_out"):
                    break
                run_participant(c, None, token=token, study=study, stop_after=1)
            browser.close()
        app.state.service.engine.dispose()
    return saved


def _wait_watched(client: httpx.Client, headers: dict, step: dict) -> None:
    """Wait until the server counts the page's replay of demonstration 0 as watched: the
    page's play end would otherwise arrive between the bot's start and end of another
    demonstration, and that play would not count."""
    deadline = time.monotonic() + len(step["demos"][0]["states"]) * step["step_ms"] / 1000 + 10
    while time.monotonic() < deadline:
        if client.get("/api/state", headers=headers).json()["step"]["completed"][0] >= 1:
            return
        time.sleep(0.1)
    raise RuntimeError("the page's demonstration replay never counted as watched")


def _stage(page, st: dict, study: dict) -> None:  # noqa: ANN001
    """Put the page in a telling state: a demonstration mid-way, a game half played."""
    s = st["step"]
    if s["kind"] == "closed_loop":
        item = s["item"]
        if item["kind"] == "demonstration":
            page.click("#play")
            page.wait_for_timeout(s["step_ms"] * (len(item["states"]) // 2))
        elif item["kind"] == "test":  # half of the naive answer (the page has no rewards)
            moves = shortest_path(item["game"])
            page.click("#board")
            for m in moves[: max(1, len(moves) // 2)]:
                page.keyboard.press(KEYS[m])
        else:  # feedback: both replays played to the end
            page.wait_for_selector("#next:not([disabled])")
    elif s["kind"] == "demos":
        page.click("#play")
        page.wait_for_selector("#board:not([data-frame='0'])")
        page.wait_for_timeout(s["step_ms"] * (len(s["demos"][0]["states"]) // 2 - 1))
    elif s["kind"] in ("test", "practice"):
        if s["kind"] == "test":
            t = find_test(study, s)
            moves = best_path(t["game"], study["domain_info"][s["domain"]]["weights"])
        else:
            moves = best_path(s["game"], s["weights"])
        page.click("#board")
        for m in moves[: max(1, len(moves) // 2)]:
            page.keyboard.press(KEYS[m])
    elif s["kind"] == "consent":
        for k in ("adult", "read", "agree"):
            page.check(f"#c-{k}")
