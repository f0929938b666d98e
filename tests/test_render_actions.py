"""Declared actions in pictures: a frame reached by `exit` or `stay` shows a marker and the
action's label in SVG, PNG, GIF and text; moves and the built-in six show none."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from actions_fixtures import EXIT, STAY, ExitDomain, domain_with
from cfteach import render
from cfteach.render import style as st

MOVES_THEN_EXIT = ["right", "right", "exit"]


def _demo(dom, actions):  # noqa: ANN001, ANN202
    inst = dom.instances()[0]
    s = inst.initial_state
    states = [inst.state_to_json(s)]
    for a in actions:
        s, _, _ = inst.step(s, dom.actions.index(a))
        states.append(inst.state_to_json(s))
    return render.layout_from_instance(inst), states


def test_exit_frame_carries_the_marker_and_label(tmp_path) -> None:  # noqa: ANN001
    dom = ExitDomain()
    layout, states = _demo(dom, MOVES_THEN_EXIT)
    frames = render.demo_frames(layout, states, MOVES_THEN_EXIT, dom.action_specs)
    assert [f.mark for f in frames[:3]] == [None, None, None]
    assert frames[-1].mark == render.ActionMark("exit", "leave the game", "exit")
    svg = render.to_svg(frames[-1])
    assert 'data-role="action:exit"' in svg and ">leave the game</text>" in svg
    assert "action:" not in render.to_svg(frames[-2])
    # the PNG has the exit colour on the agent's cell frame; the one before has none
    img = np.asarray(render.to_image(frames[-1], 48))
    before = np.asarray(render.to_image(frames[-2], 48))
    exit_rgb = tuple(int(st.EXIT_COLOR[i:i + 2], 16) for i in (1, 3, 5))
    assert (img == exit_rgb).all(axis=2).any() and not (before == exit_rgb).all(axis=2).any()
    gif = render.save_demo(layout, states, tmp_path / "d.gif", actions=MOVES_THEN_EXIT,
                           action_specs=dom.action_specs)
    with Image.open(gif) as im:
        assert im.n_frames == len(states)
    text = render.demo_text(layout, states, actions=MOVES_THEN_EXIT,
                            action_specs=dom.action_specs)
    assert text.splitlines()[-1] == f"step 3: leave the game (exit) at {list(frames[-1].agent)}"


def test_stay_gets_a_ring_and_moves_nothing() -> None:
    dom = domain_with(STAY)
    layout, states = _demo(dom, ["stay", "up"])
    frames = render.demo_frames(layout, states, ["stay", "up"], dom.action_specs)
    assert frames[1].mark.effect == "stay" and frames[2].mark is None
    assert 'data-role="action:stay"' in render.to_svg(frames[1])
    assert "wait a moment" in render.demo_text(layout, states, actions=["stay", "up"],
                                                action_specs=dom.action_specs)


def test_built_in_actions_and_no_actions_draw_as_before() -> None:
    dom = domain_with(EXIT)
    layout, states = _demo(dom, ["right", "pickup", "dropoff"])
    plain = render.demo_frames(layout, states)
    marked = render.demo_frames(layout, states, ["right", "pickup", "dropoff"],
                                dom.action_specs)
    assert [render.to_svg(f) for f in plain] == [render.to_svg(f) for f in marked]
    assert render.demo_text(layout, states) == render.demo_text(
        layout, states, actions=["right", "pickup", "dropoff"])


def test_a_wrong_number_of_actions_is_named() -> None:
    dom = domain_with(EXIT)
    layout, states = _demo(dom, ["right"])
    with pytest.raises(ValueError, match="2 states has 1 actions, got 2"):
        render.demo_frames(layout, states, ["right", "exit"])
