"""The HTML report built from hand-made JSON fixtures that follow docs/schemas.md."""

from __future__ import annotations

import copy
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cfteach.render import style as st
from cfteach.report import build_report, load_results, write_results

W_RAW = np.array([-0.175, -0.5125, -1.0])
W = (W_RAW / np.linalg.norm(W_RAW)).tolist()
FEATURES = ["skateboard_step", "path_step", "base_step"]


def state(x: int, y: int, board=None, carrying=False) -> dict:
    return {"agent": [x, y], "skateboard": board, "carrying": carrying}


def demo(env_code, start_xy, moves, *, gain, area, masked=None) -> dict:
    """A skateboard demonstration with no board, walked by hand (no path cells used)."""
    step = {"up": (0, 1), "down": (0, -1), "left": (-1, 0), "right": (1, 0)}
    x, y = start_xy
    states = [state(x, y)]
    for m in moves:
        dx, dy = step[m]
        x, y = x + dx, y + dy
        states.append(state(x, y))
    mu = [0, 0, len(moves)]
    return {
        "env_code": env_code,
        "env_index": int("".join(map(str, env_code)), 2),
        "start_state": states[0],
        "actions": list(moves),
        "states": states,
        "feature_counts": mu,
        "reward": float(np.dot(W, mu)),
        "constraints": [[0, 0, -1], [1, 0, -1]],
        "knowledge_gain": gain,
        "belief_area_after": area,
        "masked_feature": masked,
    }


def curriculum(condition: str, demos: list[dict]) -> dict:
    return {
        "schema": "cfteach.curriculum/1",
        "domain": "skateboard",
        "condition": condition,
        "profile": "default",
        "seed": 0,
        "settings": {"human_models": 8, "max_demos": None, "proportion": None},
        "feature_names": FEATURES,
        "weights": W,
        "prior": [[0, 0, -1]],
        "demos": demos,
        "final_belief": {"constraints": [[0, 0, -1], [-1, 0, 0], [0, -1, 0]], "area": math.pi / 2},
    }


def make_results() -> dict:
    curricula = {}
    for i, cond in enumerate(["baseline", "feature_only", "counterfactual_only", "proposed"]):
        demos = [
            demo([0, 0, 0], (4, 4), ["right", "right"], gain=1.5 + i, area=2.0),
            demo(
                [1, 0, 0],
                (1, 2),
                ["up", "up", "right"] + ["right"] * 4,
                gain=1.2,
                area=math.pi / 2,
                masked="path_step" if "feature" in cond else None,
            ),
        ]
        curricula[cond] = curriculum(cond, demos)
    tests = {
        "schema": "cfteach.tests/1",
        "domain": "skateboard",
        "profile": "default",
        "seed": 0,
        "settings": {"per_level": 1, "human_models": 8},
        "feature_names": FEATURES,
        "weights": W,
        "belief": {"constraints": [[0, 0, -1], [-1, 0, 0], [0, -1, 0]], "area": math.pi / 2},
        "excluded": [[0, state(4, 4)]],
        "cluster_centres": [0.1, 0.3, 0.6, 0.9, 1.2],
        "tests": {},
    }
    for k, level in enumerate(["low", "medium", "high"]):
        t = demo([0, 1, 0], (5, 3 - k), ["up"] * (1 + k), gain=None, area=None)
        for key in ("knowledge_gain", "belief_area_after", "masked_feature"):
            del t[key]
        t.update(
            overlap=1.2 - 0.5 * k,
            difficulty=level,
            all_optimal_actions=[t["actions"]],
            optimal_reward=t["reward"],
        )
        tests["tests"][level] = [t]
    return {"skateboard": {"curricula": curricula, "tests": tests}}


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.imgs: list[str] = []
        self.links: list[str] = []
        self.columns: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a["src"])
        elif tag == "a" and "href" in a and not a["href"].startswith("#"):
            self.links.append(a["href"])
        if a.get("data-condition"):
            self.columns.append(a["data-condition"])


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("report")
    results = make_results()
    write_results(out, results)
    index = build_report(out, results, sphere_resolution=24, progress=False)
    return out, index


def test_every_image_and_link_of_the_report_resolves(built):
    out, index = built
    parser = _Collect()
    parser.feed(index.read_text(encoding="utf-8"))
    assert parser.columns == ["baseline", "feature_only", "counterfactual_only", "proposed"]
    # 4 conditions x (2 demos + 1 sphere) + area chart + 3 tests + 3 overlap spheres
    assert len(parser.imgs) == 4 * 3 + 1 + 3 + 3
    for src in parser.imgs + parser.links:
        assert not re.match(r"^[a-z]+:", src), f"not a relative link: {src}"
        path = out / src
        assert path.is_file(), src
        if path.suffix in {".png", ".gif"}:
            with Image.open(path) as im:
                im.verify()
    assert (out / "skateboard" / "proposed.json").is_file()
    assert (out / "skateboard" / "tests.json").is_file()


def test_demo_gif_animates_the_walk_in_the_right_cells(built):
    out, _ = built
    cell = 48  # the report's default GIF cell size
    with Image.open(out / "skateboard/img/proposed-demo1.gif") as im:
        assert im.n_frames == 3  # start + 2 moves
        for k, x in enumerate([4, 5, 6]):
            im.seek(k)
            rgb = np.asarray(im.convert("RGB")).astype(int)
            px = rgb[int((4 - 4 + 0.6) * cell), int((x - 1 + 0.5) * cell)]
            agent = [int(st.AGENT_COLOR[i : i + 2], 16) for i in (1, 3, 5)]
            assert np.abs(px - agent).max() <= 8, (k, px)


def test_report_shows_gains_overlaps_and_summary(built):
    _, index = built
    html = index.read_text(encoding="utf-8")
    assert "gain <b>4.5</b>" in html  # proposed's first demo: 1.5 + 3
    assert "overlap <b>0.2</b>" in html  # the high test: 1.2 - 1.0
    summary = html.split('class="summary-curricula"')[1].split("</table>")[0]
    cells = re.findall(r'<td data-cell="(\w+)"><b>(\d+)</b> · ([\d.]+) · ×([\d.]+)</td>', summary)
    assert [c[0] for c in cells] == ["baseline", "feature_only", "counterfactual_only", "proposed"]
    assert all(c[1] == "2" for c in cells)
    # total knowledge gain = product of the demos' gains (baseline: 1.5 * 1.2)
    assert float(cells[0][3]) == pytest.approx(1.8)
    assert float(cells[0][2]) == pytest.approx(math.pi / 2, rel=1e-3)
    assert "profile <b>default</b>" in html and "seed <b>0</b>" in html  # read from the JSON


def test_results_round_trip_through_files(built):
    out, _ = built
    back = load_results(out)
    assert back["skateboard"].curricula == make_results()["skateboard"]["curricula"]
    assert back["skateboard"].tests["tests"]["high"][0]["overlap"] == pytest.approx(0.2)


def test_bad_results_are_named(tmp_path):
    results = make_results()
    bad = copy.deepcopy(results)
    bad["skateboard"]["curricula"]["proposed"]["schema"] = "nope"
    with pytest.raises(ValueError, match=r"curricula\['proposed'\]: not a cfteach.curriculum/1"):
        build_report(tmp_path, bad, progress=False)
    bad = copy.deepcopy(results)
    del bad["skateboard"]["tests"]["belief"]
    with pytest.raises(ValueError, match=r"tests: missing key 'belief'"):
        build_report(tmp_path, bad, progress=False)
    bad = copy.deepcopy(results)
    bad["skateboard"]["curricula"]["baseline"]["domain"] = "tiles"
    with pytest.raises(ValueError, match="its domain is 'tiles', not 'skateboard'"):
        build_report(tmp_path, bad, progress=False)
    with pytest.raises(ValueError, match="nothing to report"):
        build_report(tmp_path, {}, progress=False)


def test_report_explains_itself(built):
    _, index = built
    html = index.read_text(encoding="utf-8")
    text = " ".join(re.sub(r"<[^>]+>", " ", html).split())
    # a glossary defines the words the captions use
    for word in ("gain", "masked", "overlap", "BEC′", "area (sr)", "belief"):
        assert re.search(rf"<dt>{re.escape(word)}</dt><dd>\w", html), word
    # the belief the tests use is named as the file's posterior, not "post-teaching"
    assert "post-teaching" not in text
    assert "[beliefs] posterior" in text and "the same for every condition" in text
    # features by their labels (from the domain file), masked feature too
    assert "Skateboard ( skateboard_step ) =" in text
    assert "masked: Path" in text
    # counts agree with their nouns
    assert "1 optimal play " in text and "1 optimal plays" not in text
    assert "1 action " in text and " 1 actions" not in text
    assert "1 training demonstration excluded" in text


def test_sphere_labels_stay_clear_of_stubs_star_and_each_other():
    import matplotlib

    matplotlib.use("Agg")
    from cfteach.render import belief as bel

    for w in ([-0.6, 0.74, -0.21], W, [0.3, -0.2, -0.93], [-0.02, -0.03, -1.0]):
        fig = bel.plot_belief_sphere([[0, 0, -1]], w_true=w, feature_names=FEATURES,
                                     resolution=16)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        to_fig = fig.transFigure.inverted()
        boxes = {t.get_text(): t.get_window_extent(renderer).transformed(to_fig)
                 for t in fig.texts}
        assert {"+" + f for f in FEATURES} | {"w*"} <= set(boxes)
        for name, b in boxes.items():
            assert b.x0 >= 0 and b.x1 <= 1 and b.y0 >= 0 and b.y1 <= 1, name  # not cut off
        items = list(boxes.items())
        for i, (n1, b1) in enumerate(items):
            for n2, b2 in items[i + 1:]:
                assert not bel._overlaps(b1, b2), (n1, n2)
        # the stubs (axis lines from 1.0 to 1.25) do not run through their names
        ax = fig.axes[0]
        for k, f in enumerate(FEATURES):
            a = np.eye(3)[k]
            p0, p1 = bel._fig_xy(fig, ax, 1.0 * a), bel._fig_xy(fig, ax, 1.25 * a)
            b = boxes["+" + f]
            inside = [b.x0 < x < b.x1 and b.y0 < y < b.y1
                      for x, y in (p0 + (p1 - p0) * s for s in np.linspace(0, 1, 21))]
            assert not any(inside), f
        # "w*" is beside its star, not on it
        star = bel._fig_xy(fig, ax, np.asarray(w) / np.linalg.norm(w))
        b = boxes["w*"]
        assert not (b.x0 < star[0] < b.x1 and b.y0 < star[1] < b.y1)


def test_demo_gif_marks_a_declared_exit_action(tmp_path):
    """A demonstration ending with a declared `exit` (skateboard + exit, given to the report
    as its domain file) shows the exit marker on the GIF's last frame only."""
    from actions_fixtures import EXIT, domain_with

    results = make_results()
    for cur in results["skateboard"]["curricula"].values():
        d = cur["demos"][0]
        d["actions"] = [*d["actions"], "exit"]
        d["states"] = [*d["states"], d["states"][-1]]
    dom = domain_with(EXIT, name="skateboard", base="skateboard")
    build_report(tmp_path, results, sphere_resolution=12, progress=False,
                 meta={"domain_files": {"skateboard": dom}})
    exit_rgb = [int(st.EXIT_COLOR[i : i + 2], 16) for i in (1, 3, 5)]
    with Image.open(tmp_path / "skateboard/img/proposed-demo1.gif") as im:
        assert im.n_frames == 4
        seen = []
        for k in range(4):
            im.seek(k)
            rgb = np.asarray(im.convert("RGB")).astype(int)
            seen.append(bool((np.abs(rgb - exit_rgb).max(axis=2) <= 8).any()))
    assert seen == [False, False, False, True]
