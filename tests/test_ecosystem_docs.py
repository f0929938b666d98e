"""The examples of docs/ecosystem.md run as written (the imitation block against a stand-in
with imitation's own Trajectory checks: the package cannot be installed beside cfteach)."""

from __future__ import annotations

import re

import pytest
import typer

from cfteach.cli import app
from doc_examples import DOCS, code_blocks, run_script

DOC = DOCS / "ecosystem.md"
BLOCKS = code_blocks("ecosystem.md")

#: imitation.data.types.Trajectory / TrajectoryWithRew's checks (imitation 1.0.1), so the
#: conversion is tested against the contract it must meet.
IMITATION_STAND_IN = '''
import sys, types, dataclasses
import numpy as np

@dataclasses.dataclass(frozen=True)
class Trajectory:
    obs: np.ndarray
    acts: np.ndarray
    infos: object
    terminal: bool
    def __post_init__(self):
        if len(self.obs) != len(self.acts) + 1:
            raise ValueError("expected one more observation than actions")
        if self.infos is not None and len(self.infos) != len(self.acts):
            raise ValueError("infos must have one entry per action")
        if len(self.acts) == 0:
            raise ValueError("Degenerate trajectory: must have at least one action.")

@dataclasses.dataclass(frozen=True)
class TrajectoryWithRew(Trajectory):
    rews: np.ndarray = None
    def __post_init__(self):
        super().__post_init__()
        if self.rews.shape != (len(self.acts),):
            raise ValueError("rewards must have one entry per action")
        if not np.issubdtype(self.rews.dtype, np.floating):
            raise ValueError("rewards must be floats")

mod = types.ModuleType("imitation.data.types")
mod.Trajectory, mod.TrajectoryWithRew = Trajectory, TrajectoryWithRew
sys.modules["imitation"] = types.ModuleType("imitation")
sys.modules["imitation.data"] = types.ModuleType("imitation.data")
sys.modules["imitation.data.types"] = mod
'''


@pytest.fixture(autouse=True)
def minari_root(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))


def test_the_doc_has_its_three_examples():
    assert len(BLOCKS) == 3
    assert "minari.load_dataset" in BLOCKS[0] and "TrajectoryWithRew" in BLOCKS[1]
    assert "value_iteration" in BLOCKS[2]


def test_reading_answers_with_minari_and_converting_them_for_imitation(tmp_path):
    check = ("\nassert len(trajectories) == dataset.total_episodes > 0\n"
             "assert all(isinstance(t.terminal, bool) for t in trajectories)\n"
             "print(len(trajectories), 'trajectories')\n")
    done = run_script(IMITATION_STAND_IN + BLOCKS[0] + BLOCKS[1] + check, tmp_path)
    lines = done.stdout.splitlines()
    assert re.fullmatch(r"12 answers; \['\w+', '\w+'\]", lines[0])
    assert lines[1] == "12 trajectories"


def test_the_irl_example_recovers_a_reward_whose_policy_matches_and_prints_as_shown(tmp_path):
    done = run_script(BLOCKS[2], tmp_path, timeout=120)
    shown = re.search(r"It prints\n\n```\n(.*?)```", DOC.read_text(encoding="utf-8"), re.S)
    assert shown is not None
    assert done.stdout == shown.group(1)


def test_the_commands_shown_use_existing_options():
    text = DOC.read_text(encoding="utf-8")
    commands = re.findall(r"\$ cfteach export minari (\w+)((?:[^\n]|\\\n)*)", text)
    assert {c for c, _ in commands} == {"demos", "answers", "check"}
    group = typer.main.get_command(app).commands["export"].commands["minari"]
    for sub, rest in commands:
        known = {o for p in group.commands[sub].params for o in (*p.opts, *p.secondary_opts)}
        for option in re.findall(r"--[\w-]+", rest):
            assert option in known, (sub, option)
