"""Grid rendering puts every thing in the right cell, in every output format.

The expected positions are worked out by hand from the layout (1-based x, y up; the picture
has row `height` on top), not read back from the renderer's own geometry code.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from cfteach import render
from cfteach.render import style as st
from cfteach.render.scene import Layout

C = 40  # cell size in pixels for the tests


def hex_rgb(color: str) -> tuple[int, int, int]:
    color = color.lstrip("#")
    return tuple(int(color[i : i + 2], 16) for i in (0, 2, 4))  # type: ignore[return-value]


def pixel(img: np.ndarray, height: int, cell: tuple[int, int], fx: float, fy: float) -> tuple:
    """Colour at fraction (fx, fy) of a cell, from the cell's top-left corner (by hand)."""
    x, y = cell
    px = int((x - 1 + fx) * C)
    py = int((height - y + fy) * C)
    return tuple(int(v) for v in img[py, px, :3])


@pytest.fixture
def delivery_like() -> Layout:
    return Layout(
        width=4,
        height=3,
        walls=frozenset({(1, 3), (1, 2)}),
        cell_sets=(("mud", frozenset({(3, 2)})),),
        goal=(1, 1),
        goal_is_destination=True,
        cargo="passenger",
        consumables=(("station", (4, 3)),),
    )


@pytest.fixture
def skate_like() -> Layout:
    return Layout(
        width=6,
        height=4,
        cell_sets=(("path", frozenset({(1, 1), (2, 1), (3, 1)})),),
        goal=(6, 4),
        cargo="skateboard",
    )


START = {"agent": [2, 1], "passenger": [4, 2], "carrying": False, "station": True}


def test_png_puts_agent_objects_walls_mud_and_destination_in_their_cells(delivery_like):
    img = render.to_rgb_array(render.scene_from_state_json(delivery_like, START), C)
    assert img.shape == (3 * C + 1, 4 * C + 1, 3)
    H = 3
    assert pixel(img, H, (2, 1), 0.5, 0.6) == hex_rgb(st.AGENT_COLOR)
    assert pixel(img, H, (4, 2), 0.5, 0.5) == hex_rgb(st.OBJECT_STYLES["passenger"].color)
    assert pixel(img, H, (4, 3), 0.5, 0.5) == hex_rgb(st.OBJECT_STYLES["station"].color)
    for wall in [(1, 3), (1, 2)]:
        assert pixel(img, H, wall, 0.5, 0.5) == hex_rgb(st.WALL_COLOR)
    assert pixel(img, H, (3, 2), 0.1, 0.1) == hex_rgb(st.CELL_STYLES["mud"].color)
    # destination: a small square in the package's colour at the centre of (1, 1)
    assert pixel(img, H, (1, 1), 0.5, 0.5) == hex_rgb(st.OBJECT_STYLES["passenger"].color)
    assert pixel(img, H, (1, 1), 0.1, 0.1) == hex_rgb(st.BACKGROUND)
    # nothing drawn in an empty cell, and the agent is nowhere else
    assert pixel(img, H, (3, 3), 0.5, 0.5) == hex_rgb(st.BACKGROUND)
    blue = np.all(img == np.array(hex_rgb(st.AGENT_COLOR)), axis=-1)
    ys, xs = np.nonzero(blue)
    assert xs.min() >= 1 * C and xs.max() < 2 * C  # column of x = 2
    assert ys.min() >= 2 * C and ys.max() < 3 * C  # bottom row (y = 1)


def test_carried_cargo_is_drawn_at_the_agents_top_right_and_consumed_station_vanishes(
    delivery_like,
):
    state = {"agent": [3, 3], "passenger": [3, 3], "carrying": True, "station": False}
    img = render.to_rgb_array(render.scene_from_state_json(delivery_like, state), C)
    purple = hex_rgb(st.OBJECT_STYLES["passenger"].color)
    assert pixel(img, 3, (3, 3), 0.8, 0.2) == purple
    assert pixel(img, 3, (4, 2), 0.5, 0.5) == hex_rgb(st.BACKGROUND)
    green = np.all(img == np.array(hex_rgb(st.OBJECT_STYLES["station"].color)), axis=-1)
    assert not green.any()


def test_svg_elements_name_their_cells(delivery_like):
    svg = render.to_svg(render.scene_from_state_json(delivery_like, START), C)
    root = ET.fromstring(svg)
    by_role: dict[str, set] = {}
    for el in root.iter():
        role = el.get("data-role")
        if role and el.get("data-cell"):
            x, y = (int(v) for v in el.get("data-cell").split(","))
            by_role.setdefault(role, set()).add((x, y))
    assert by_role["agent"] == {(2, 1)}
    assert by_role["object:passenger"] == {(4, 2)}
    assert by_role["object:station"] == {(4, 3)}
    assert by_role["wall"] == {(1, 3), (1, 2)}
    assert by_role["cell:mud"] == {(3, 2)}
    assert by_role["goal"] == {(1, 1)}
    # the agent's triangle lies inside its cell's pixel box: x in [40, 80], y in [80, 120]
    agent = next(el for el in root.iter() if el.get("data-role") == "agent")
    pts = [tuple(float(v) for v in p.split(",")) for p in agent.get("points").split()]
    assert all(C <= px <= 2 * C and 2 * C <= py <= 3 * C for px, py in pts)
    assert agent.get("fill") == st.AGENT_COLOR


def test_trail_is_drawn_through_visited_cells(skate_like):
    states = [{"agent": [x, 4], "skateboard": None, "carrying": False} for x in (3, 4, 5, 6)]
    frames = render.demo_frames(skate_like, states)
    assert [f.trail for f in frames][-1] == ((3, 4), (4, 4), (5, 4), (6, 4))
    root = ET.fromstring(render.to_svg(frames[-1], C))
    dots = {el.get("data-cell") for el in root.iter() if el.get("data-role") == "trail"}
    assert dots == {"4,4", "5,4", "6,4"}
    starts = [el.get("data-cell") for el in root.iter() if el.get("data-role") == "trail-start"]
    assert starts == ["3,4"]
    img = render.to_rgb_array(frames[-1], C)
    assert pixel(img, 4, (4, 4), 0.5, 0.5) == hex_rgb(st.TRAIL_COLOR)
    # the trail line does not touch cells off the walk
    assert pixel(img, 4, (4, 3), 0.5, 0.5) == hex_rgb(st.BACKGROUND)


def test_text_rendering_by_hand(delivery_like):
    scene = render.scene_from_state_json(delivery_like, START, trail=[(3, 1), (2, 1)])
    expected = "\n".join(
        [
            "+----+",
            "|#  h|",  # y = 3: wall at x=1, station at x=4
            "|# ~p|",  # y = 2: wall, mud at x=3, package at x=4
            "|d@. |",  # y = 1: destination, agent, trail
            "+----+",
        ]
    )
    assert render.to_text(scene) == expected
    carrying = {"agent": [4, 2], "passenger": [4, 2], "carrying": True, "station": True}
    lines = render.to_text(render.scene_from_state_json(delivery_like, carrying)).splitlines()
    assert lines[2] == "|# ~&|"
    assert "\x1b[" in render.to_text(scene, color=True)
    assert "h station" in render.legend(delivery_like)


def test_generic_styles_for_user_domain_names():
    lay = Layout(
        width=3,
        height=1,
        cell_sets=(("lava", frozenset({(1, 1)})), ("ice", frozenset({(2, 1)}))),
        cargo="key",
        consumables=(("coin", (3, 1)),),
    )
    state = {"agent": [2, 1], "key": [1, 1], "carrying": False, "coin": True}
    scene = render.scene_from_state_json(lay, state)
    img = render.to_rgb_array(scene, C)
    lava, ice = st.cell_style("lava", 0), st.cell_style("ice", 1)
    assert lava.color != ice.color
    assert pixel(img, 1, (1, 1), 0.05, 0.05) == hex_rgb(lava.color)
    assert pixel(img, 1, (2, 1), 0.05, 0.05) == hex_rgb(ice.color)
    assert pixel(img, 1, (1, 1), 0.5, 0.5) == hex_rgb(st.object_style("key", "cargo").color)
    coin = st.object_style("coin", "consumable").color
    assert coin != st.object_style("key", "cargo").color
    assert st.object_style("coin", "consumable").char != st.object_style("key", "cargo").char
    assert pixel(img, 1, (3, 1), 0.5, 0.5) == hex_rgb(coin)
    key_char = st.object_style("key", "cargo").char
    coin_char = st.object_style("coin", "consumable").char
    assert render.to_text(scene, border=False) == f"{key_char}@{coin_char}"


def test_bad_input_names_the_problem(delivery_like):
    with pytest.raises(ValueError, match=r"state\.agent.*off the 4x3 grid"):
        render.scene_from_state_json(delivery_like, {**START, "agent": [5, 1]})
    with pytest.raises(ValueError, match="no 'agent'"):
        render.scene_from_state_json(delivery_like, {"passenger": [1, 1]})
    with pytest.raises(ValueError, match="carrying but 'passenger' is null"):
        render.scene_from_state_json(delivery_like, {**START, "passenger": None, "carrying": True})
    with pytest.raises(ValueError, match="station must be true/false"):
        render.scene_from_state_json(delivery_like, {**START, "station": 1})
    with pytest.raises(ValueError, match="unknown picture format"):
        render.save_demo(delivery_like, [START], "x.bmp")


def test_gif_has_one_frame_per_state_with_the_agent_moving(tmp_path: Path, skate_like):
    cells = [(4, 4), (3, 4), (3, 3), (2, 3)]
    states = [{"agent": list(c), "skateboard": [1, 4], "carrying": False} for c in cells]
    path = render.save_demo(skate_like, states, tmp_path / "demo.gif", cell_px=C)
    with Image.open(path) as im:
        assert im.n_frames == len(states)
        for k, cell in enumerate(cells):
            im.seek(k)
            rgb = np.asarray(im.convert("RGB"))
            got = np.array(pixel(rgb, 4, cell, 0.5, 0.6))
            assert np.abs(got - hex_rgb(st.AGENT_COLOR)).max() <= 8, (k, cell, got)
    first = render.save_demo(skate_like, states, tmp_path / "f.png", cell_px=C, still="first")
    rgb = np.asarray(Image.open(first).convert("RGB"))
    assert pixel(rgb, 4, (4, 4), 0.5, 0.6) == hex_rgb(st.AGENT_COLOR)  # at the start
    assert pixel(rgb, 4, (2, 3), 0.5, 0.5) == hex_rgb(st.TRAIL_COLOR)  # the path to come
    png = render.save_demo(skate_like, states, tmp_path / "demo.png", cell_px=C)
    rgb = np.asarray(Image.open(png).convert("RGB"))
    assert pixel(rgb, 4, (2, 3), 0.5, 0.6) == hex_rgb(st.AGENT_COLOR)
    assert pixel(rgb, 4, (1, 4), 0.5, 0.5) == hex_rgb(st.OBJECT_STYLES["skateboard"].color)
    assert pixel(rgb, 4, (6, 4), 0.5, 0.5) == hex_rgb(st.GOAL_COLOR)
    assert pixel(rgb, 4, (2, 1), 0.1, 0.1) == hex_rgb(st.CELL_STYLES["path"].color)


def test_legend_icons_draw_each_kind_with_its_own_style(delivery_like):
    from cfteach.render.svg import legend_icons

    icons = dict(legend_icons(delivery_like))
    assert list(icons) == [
        "robot",
        "path walked",
        "wall",
        "mud",
        "destination",
        "package (passenger)",
        "battery station (station)",
    ]
    fills = {
        label: {e.get("fill") for e in ET.fromstring(svg).iter() if e.get("data-role")}
        for label, svg in icons.items()
    }
    assert fills["robot"] == {st.AGENT_COLOR}
    assert fills["mud"] == {st.CELL_STYLES["mud"].color}
    assert fills["wall"] == {st.WALL_COLOR}
    assert fills["battery station (station)"] == {st.OBJECT_STYLES["station"].color}
    assert fills["package (passenger)"] == {st.OBJECT_STYLES["passenger"].color}
