"""Pictures of grids and demonstrations in the study's visual language.

Layers: `scene` (what is on the grid: `Layout` + state -> `Scene`), `shapes` (scene ->
drawing primitives), then writers: `svg`, `raster` (PNG, `rgb_array`, GIF), `text` (one
character per cell). `belief` draws regions of reward weights on the sphere (matplotlib).

Typical use::

    from cfteach import domains, render
    inst = domains.load("delivery").instances()[5]
    print(render.text_of(inst, inst.initial_state))
    render.save(inst, inst.initial_state, "start.svg")
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from cfteach.render._adapt import layout_from_instance
from cfteach.render.raster import save_gif, save_png, to_image, to_rgb_array
from cfteach.render.scene import (
    ActionMark,
    Layout,
    Scene,
    SceneObject,
    action_mark,
    scene_from_state_json,
    trail_of,
)
from cfteach.render.svg import to_svg
from cfteach.render.text import legend, to_text

__all__ = [
    "ActionMark",
    "Layout",
    "Scene",
    "SceneObject",
    "action_mark",
    "demo_frames",
    "demo_text",
    "layout_from_instance",
    "legend",
    "save",
    "save_demo",
    "save_gif",
    "save_png",
    "scene_from_state_json",
    "scene_of",
    "text_of",
    "to_image",
    "to_rgb_array",
    "to_svg",
    "to_text",
    "trail_of",
]


def _state_json(instance: Any, state: Any) -> Mapping[str, Any]:
    if isinstance(state, Mapping):
        return state
    return instance.state_to_json(state)


def scene_of(instance: Any, state: Any, trail: Sequence[Sequence[int]] = ()) -> Scene:
    """The scene of an instance in `state` (a State tuple or its JSON dict)."""
    return scene_from_state_json(
        layout_from_instance(instance), _state_json(instance, state), trail
    )


def text_of(instance: Any, state: Any, trail: Sequence[Sequence[int]] = (), **kw: Any) -> str:
    """One character per cell (see `cfteach.render.text`)."""
    return to_text(scene_of(instance, state, trail), **kw)


def save(
    instance: Any,
    state: Any,
    path: str | Path,
    *,
    trail: Sequence[Sequence[int]] = (),
    cell_px: int = 48,
) -> Path:
    """Write one state as `.svg`, `.png` or `.txt`, chosen by the file suffix."""
    return _write(scene_of(instance, state, trail), Path(path), cell_px)


def _write(scene: Scene, path: Path, cell_px: int) -> Path:
    suffix = path.suffix.lower()
    if suffix == ".svg":
        path.write_text(to_svg(scene, cell_px), encoding="utf-8")
    elif suffix == ".png":
        save_png(scene, path, cell_px)
    elif suffix == ".txt":
        path.write_text(to_text(scene) + "\n", encoding="utf-8")
    else:
        raise ValueError(f"{path}: unknown picture format {suffix!r}; use .svg, .png or .txt")
    return path


def demo_frames(
    layout: Layout,
    states: Sequence[Mapping[str, Any]],
    actions: Sequence[str] = (),
    action_specs: Sequence[Any] = (),
) -> list[Scene]:
    """One scene per state of a demonstration, each with the trail walked so far. With the
    demonstration's `actions` (and the domain's `action_specs`; built-ins by default), a
    frame reached by an `exit` or `stay` action carries that action's marker and label."""
    if not states:
        raise ValueError("a demonstration needs at least one state")
    if actions and len(actions) != len(states) - 1:
        raise ValueError(f"a demonstration with {len(states)} states has {len(states) - 1} "
                         f"actions, got {len(actions)}")
    frames = []
    for k, s in enumerate(states):
        scene = scene_from_state_json(layout, s, trail_of(states[: k + 1]), done=False)
        if k and actions:
            scene = replace(scene, mark=action_mark(actions[k - 1], action_specs))
        frames.append(scene)
    return frames


def save_demo(
    layout: Layout,
    states: Sequence[Mapping[str, Any]],
    path: str | Path,
    *,
    cell_px: int | None = None,
    frame_ms: int = 450,
    still: str = "last",
    actions: Sequence[str] = (),
    action_specs: Sequence[Any] = (),
) -> Path:
    """A demonstration as an animated `.gif`, or one still with the whole trail as
    `.png`/`.svg`/`.txt`: `still="last"` shows where it ends, `still="first"` shows the start
    (objects where they begin, as a test looks to a player) with the path to come.
    `actions`/`action_specs`: mark `exit` and `stay` actions (see `demo_frames`)."""
    path = Path(path)
    frames = demo_frames(layout, states, actions, action_specs)
    if path.suffix.lower() == ".gif":
        return save_gif(frames, path, cell_px or 32, frame_ms=frame_ms)
    if still not in ("first", "last"):
        raise ValueError(f"still must be 'first' or 'last', got {still!r}")
    scene = frames[-1] if still == "last" else replace(frames[0], trail=frames[-1].trail)
    return _write(scene, path, cell_px or 48)


def demo_text(
    layout: Layout,
    states: Sequence[Mapping[str, Any]],
    *,
    color: bool = False,
    actions: Sequence[str] = (),
    action_specs: Sequence[Any] = (),
) -> str:
    """A demonstration in text: its last frame with the whole trail, then the legend, then
    one line per `exit` / `stay` action taken (with `actions`), naming it and its cell."""
    frames = demo_frames(layout, states, actions, action_specs)
    lines = [to_text(frames[-1], color=color), legend(layout)]
    for k, f in enumerate(frames):
        if f.mark is not None:
            lines.append(f"step {k}: {f.mark.label} ({f.mark.name}) at {list(f.agent)}")
    return "\n".join(lines)
