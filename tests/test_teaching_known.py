"""Teaching with the step weight known (the 2021 work's setting), end to end: the 2021 taxi's
policy constraints, gains and test overlaps on the slice checked against brute-force grids of
the slice, `[beliefs] known` in domain files, `--known` errors, and the slice pictures."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cfteach.cli import app
from cfteach.domains import DomainFileError, load
from cfteach.geometry.slice import KnownSlice
from cli_runner import WideRunner

runner = WideRunner()
ROOT = Path(__file__).resolve().parents[1]
TAXI = ROOT / "examples" / "domains" / "augmented_taxi_2021.toml"
POLICY_2021 = {(1, 5, 11), (-1, -6, -9)}


def _grid(sl: KnownSlice, fine: bool = True) -> tuple[np.ndarray, float]:
    """Whole weight vectors on a fine grid of the slice, and each point's share of the
    measure (the perimeter for the edge, the diamond's area for the ball)."""
    r = sl.radius
    if sl.measure == "edge":
        n = 100_000 if fine else 20_000
        sq = np.array([[r, 0.0], [0.0, r], [-r, 0.0], [0.0, -r]])
        s = (np.arange(n) + 0.5) / n
        u = np.vstack([sq[j] + s[:, None] * (sq[(j + 1) % 4] - sq[j]) for j in range(4)])
        cell = r * math.sqrt(2) / n
    else:
        n = 2001 if fine else 401
        x = (np.arange(n) + 0.5) / n * 2 * r - r
        u = np.stack(np.meshgrid(x, x, indexing="ij"), axis=-1).reshape(-1, 2)
        u = u[np.abs(u).sum(axis=1) <= r]
        cell = (2 * r / n) ** 2
    return sl.lift(u), cell


def _measure(pts: np.ndarray, cell: float, rows) -> float:  # noqa: ANN001
    rows = np.asarray(rows, dtype=float).reshape(-1, pts.shape[1])
    return float((pts @ rows.T >= 0).all(axis=1).sum() * cell) if len(rows) else \
        len(pts) * cell


def _taxi_with_known(tmp_path: Path) -> Path:
    path = tmp_path / "taxi_known.toml"
    path.write_text(TAXI.read_text() + '\n[beliefs]\nknown = ["step"]\n')
    return path


def test_teach_2021_taxi_baseline_known_step_ends_on_the_2021_policy_constraints(
        tmp_path: Path) -> None:
    """`cfteach teach <2021 taxi> --condition baseline --known step` ends on the 2021 policy
    constraints [1, 5, 11] and [-1, -6, -9]; its set cover needs two demonstrations, each
    covering one of them; the final belief is the policy BEC's region on a grid."""
    from cfteach.bec import policy_bec
    from cfteach.teaching import teach

    out = tmp_path / "cur.json"
    res = runner.invoke(app, ["teach", str(TAXI), "--condition", "baseline", "--known", "step",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    assert {tuple(r) for r in data["final_belief"]["constraints"]} == POLICY_2021
    assert data["settings"]["known"] == {"features": ["step"], "weights": [-1 / 30],
                                         "measure": "ball"}
    cur = teach(load(TAXI), "baseline", known=["step"])
    assert cur.to_json() == {**data, "settings": data["settings"]}
    scot = cur.log[0]["scot"]
    assert len(scot) == 2 and cur.demo_indices[-2:] == scot
    covered = [{tuple(r) for r in rec.constraints.tolist()} & POLICY_2021
               for rec in cur.records[-2:]]
    assert all(len(c) == 1 for c in covered) and set.union(*covered) == POLICY_2021
    # independent: the final belief's measure is the grid measure of the policy BEC (which
    # test_domains_actions checks against the grid too)
    sl = KnownSlice.make(load(TAXI).weights_raw, [2], "ball")
    pts, cell = _grid(sl)
    assert data["final_belief"]["area"] == pytest.approx(
        _measure(pts, cell, policy_bec(TAXI, known=["step"])), rel=0.03)


@pytest.mark.parametrize(("condition", "profile"), [("feature_only", "reference"),
                                                    ("proposed", "default")])
def test_gains_are_ratios_of_slice_measures(condition: str, profile: str) -> None:
    """Each demonstration's knowledge gain and belief measure on the slice, against a grid of
    the slice (reference: edge lengths; default: ball areas); the known feature is never
    masked; human models keep the known weight."""
    from cfteach.teaching import teach

    cur = teach(load(TAXI), condition, known=["step"], profile=profile, envs=":16",
                max_demos=4)
    data = cur.to_json()
    sl = KnownSlice.make(load(TAXI).weights_raw, [2], "edge" if profile == "reference"
                         else "ball")
    assert data["settings"]["known"]["measure"] == sl.measure
    pts, cell = _grid(sl)
    rows = np.zeros((0, 3))
    before = _measure(pts, cell, rows)
    for demo in data["demos"]:
        rows = np.vstack([rows, demo["constraints"]])
        after = _measure(pts, cell, rows)
        assert demo["belief_area_after"] == pytest.approx(after, rel=0.03, abs=1e-4)
        if condition == "feature_only":  # recorded gains are before / after here
            assert demo["knowledge_gain"] == pytest.approx(before / after, rel=0.03)
        assert demo["masked_feature"] != "step"
        before = after
    for entry in cur.log:
        for w in entry.get("human_models", []):
            assert w[2] == pytest.approx(-1 / 30)
            if profile == "reference":
                assert sum(map(abs, w)) == pytest.approx(1.0)


def test_tests_overlaps_are_slice_measures() -> None:
    """Test difficulty on the slice: each selected test's overlap is the grid measure of the
    posterior cut by its constraints; the JSON records the slice."""
    from cfteach.teaching import select_tests

    ts = select_tests(load(TAXI), known=["step"], envs=":8", per_level=2)
    data = ts.to_json()
    assert data["settings"]["known"]["features"] == ["step"]
    sl = KnownSlice.make(load(TAXI).weights_raw, [2], "ball")
    pts, cell = _grid(sl)
    n = 0
    for level in ("low", "medium", "high"):
        for t in data["tests"][level]:
            assert t["overlap"] == pytest.approx(_measure(pts, cell, t["constraints"]),
                                                 rel=0.03, abs=1e-4)
            n += 1
    assert n >= 3
    for w in data["human_models"]:
        assert w[2] == pytest.approx(-1 / 30)


def test_beliefs_known_in_a_domain_file_equals_the_option(tmp_path: Path) -> None:
    from cfteach.teaching import teach

    dom = load(_taxi_with_known(tmp_path))
    assert dom.spec.known == ("step",)
    by_file = teach(dom, "baseline", envs=":4", max_demos=3).to_json()
    by_arg = teach(load(TAXI), "baseline", envs=":4", max_demos=3, known=["step"]).to_json()
    assert by_file["settings"]["known"] == by_arg["settings"]["known"]
    assert by_file["demos"] == by_arg["demos"]
    # --known none overrides the file: the sphere again, no settings.known
    none = teach(dom, "baseline", envs=":4", max_demos=3, known="none").to_json()
    plain = teach(load(TAXI), "baseline", envs=":4", max_demos=3).to_json()
    assert "known" not in none["settings"] and "known" not in plain["settings"]
    assert none["demos"] == plain["demos"]


@pytest.mark.parametrize(("known", "problem"), [
    ('["speed"]', "unknown feature 'speed'"),
    ('["step", "step"]', "listed twice"),
    ('["step", "toll"]', "fewer than two unknown weights"),
    ('"step"', "must be a list"),
])
def test_beliefs_known_errors_name_the_key(tmp_path: Path, known: str, problem: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(TAXI.read_text() + f"\n[beliefs]\nknown = {known}\n")
    with pytest.raises(DomainFileError, match="beliefs.known") as err:
        load(path)
    assert problem in str(err.value)


@pytest.mark.parametrize("cmd", [["teach"], ["tests"]])
def test_known_option_errors_are_one_line(cmd: list[str]) -> None:
    for value, problem in (("speed", "unknown feature(s) 'speed'"),
                           ("step,toll", "at least two must stay unknown")):
        res = runner.invoke(app, [*cmd, str(TAXI), "--known", value])
        assert res.exit_code == 2, res.output
        assert "--known" in res.output and problem in res.output
        assert "Traceback" not in res.output


def test_slice_pictures_draw_arcs_and_polygons() -> None:
    """A curriculum JSON with settings.known is drawn on the slice (a 2-D plot, not a
    sphere): on the edge as segments whose total length is the belief's grid length; in the
    ball as a filled polygon whose area is the belief's grid area."""
    import matplotlib

    matplotlib.use("Agg")
    from cfteach.render.belief_slice import belief_picture

    rows = [[1, 5, 11], [-1, -6, -9], [1, 0, 0]]
    for measure in ("edge", "ball"):
        data = {"settings": {"known": {"features": ["step"], "measure": measure}},
                "weights": [26 / 30, -3 / 30, -1 / 30],
                "feature_names": ["delivered", "toll", "step"]}
        fig = belief_picture(rows, data=data, labels=["Delivered", "Toll", "Step"], title="t")
        ax = fig.axes[0]
        assert ax.name == "rectilinear"
        sl = KnownSlice.make(data["weights"], [2], measure)
        pts, cell = _grid(sl)
        truth = _measure(pts, cell, rows)
        if measure == "edge":
            green = [ln for ln in ax.lines if ln.get_label() == "belief"
                     or (ln.get_color() == "#2e9d4a")]
            drawn = sum(float(np.linalg.norm(np.diff(ln.get_xydata(), axis=0), axis=1).sum())
                        for ln in green)
            assert drawn == pytest.approx(truth, rel=0.01)
        else:
            poly = [p for p in ax.patches if p.get_label() == "belief"]
            assert len(poly) == 1
            xy = poly[0].get_xy()
            x, y = xy[:, 0], xy[:, 1]
            area = 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))
            assert area == pytest.approx(truth, rel=0.03)
        assert "known: Step = -0.0333" in ax.get_title()


@pytest.mark.parametrize(("envs", "n_differ"), [(":16", 82), ("0::16", 41)])
def test_edge_and_ball_one_step_sets_differ_by_interior_rows(envs: str, n_differ: int) -> None:
    """Where the measures agree the reductions agree: the edge's (2021) and the ball's one-step
    sets differ only by one row that cuts the ball's interior but not its edge (checked on
    grids of both). The counts are the 82 + 41 candidates of the earlier candidate-by-
    candidate comparison with the 2021 code, whose sets lacked exactly such a row."""
    from cfteach.bec.demos import demo_set
    from cfteach.domains import subset
    from cfteach.teaching import known

    dom = subset(load(TAXI), envs)
    ds = demo_set(dom, "default")
    ball = KnownSlice.make(dom.weights_raw, [2], "ball")
    edge = KnownSlice.make(dom.weights_raw, [2], "edge")
    sb, se = known.one_step_sets(ds, ball), known.one_step_sets(ds, edge)
    pts_e, _ = _grid(edge, fine=False)
    pts_b, _ = _grid(ball, fine=False)
    differ = 0
    for d in range(ds.D):
        b = {tuple(r) for r in sb[d].tolist()}
        e = {tuple(r) for r in se[d].tolist()}
        if b == e:
            continue
        differ += 1
        assert e < b and len(b - e) == 1
        extra = np.array(next(iter(b - e)), dtype=float)
        rest = np.array(sorted(e), dtype=float).reshape(-1, 3)
        on_e = (pts_e @ rest.T >= 0).all(axis=1) if len(rest) else np.ones(len(pts_e), bool)
        on_b = (pts_b @ rest.T >= 0).all(axis=1) if len(rest) else np.ones(len(pts_b), bool)
        assert (pts_e[on_e] @ extra >= -1e-9).all()  # the edge never feels it
        assert (pts_b[on_b] @ extra < 0).any()  # the ball's interior does
    assert differ == n_differ


@pytest.mark.parametrize("cmd", [
    ["reproduce", "--domains", str(TAXI), "--no-report", "--known", "speed", "--out", "{tmp}"],
    ["simulate", "--domains", str(TAXI), "--known", "speed", "--out", "{tmp}"],
    ["study", "init", "--domains", str(TAXI), "--known", "speed", "--out", "{tmp}"],
])
def test_known_is_checked_before_any_work(cmd: list[str], tmp_path: Path) -> None:
    args = [a.replace("{tmp}", str(tmp_path / "out")) for a in cmd]
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "--known" in res.output and "'speed'" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "out" / "augmented_taxi_2021").exists()


def test_study_init_known_needs_teaching_here(tmp_path: Path) -> None:
    res = runner.invoke(app, ["study", "init", "--toy", "--known", "step",
                              "--out", str(tmp_path / "s")])
    assert res.exit_code == 2 and "--known applies when teaching here" in res.output


def test_report_draws_the_slice_and_says_what_is_known(tmp_path: Path) -> None:
    """A report of curricula taught with the step known: a 2-D slice picture per condition
    (not a sphere) and a line naming the known weight and the measure."""
    import matplotlib

    matplotlib.use("Agg")
    from PIL import Image

    from cfteach.report import build_report
    from cfteach.report.build import DomainResults, default_layouts
    from cfteach.teaching import teach

    dom = load(TAXI)
    cur = teach(dom, "baseline", known=["step"], envs=":4", max_demos=2,
                profile="reference").to_json()
    res = {dom.name: DomainResults(curricula={"baseline": cur})}
    index = build_report(tmp_path, res, layouts=default_layouts({dom.name: dom}),
                         progress=False)
    html = index.read_text()
    assert "known weights" in html and "edge of the L1 ball" in html
    img = next(tmp_path.rglob("baseline-belief.png"))
    assert Image.open(img).size == (420, 420)  # the slice figure's size, not the sphere's
