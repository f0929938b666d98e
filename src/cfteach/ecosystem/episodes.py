"""Episodes in the Gymnasium view: the robot's demonstrations and people's test answers,
each replayed through `cfteach.gym.GridEnv` (state observations) so that what a dataset
stores is exactly what the registered environment gives back."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: Reward columns are stored with repr(); a replay must agree with them to this tolerance.
REWARD_TOL = 1e-9


@dataclass
class Episode:
    """One episode: `observations` `[T+1, K]` (env bits + State), `actions` `[T]`, `rewards`
    `[T]` (w* . phi), how it ended, the reset options that reproduce its start and metadata
    (participant, condition, test, ...)."""

    env_code: str
    start_state: dict[str, Any]
    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: bool
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def options(self) -> dict[str, str]:
        """`reset(options=...)` that starts this episode (strings: they survive any storage)."""
        return {"env_code": self.env_code,
                "start_state": json.dumps(self.start_state, sort_keys=True)}

    @property
    def total_reward(self) -> float:
        return float(self.rewards.sum())


def _bits(code: Sequence[int]) -> str:
    return "".join(str(int(b)) for b in code)


def episode_env(domain: Any, max_steps: int) -> Any:
    """The environment that records episodes: state observations, `max_steps` per episode."""
    from cfteach import gym as cgym

    return cgym.make(domain, observation="state", max_steps=max_steps)


def play(env: Any, env_code: str, start_state: dict[str, Any], actions: Sequence[int],
         metadata: dict[str, Any], what: str) -> Episode:
    """Replay `actions` from a start in `env` and record the episode (ValueError names
    `what` when the actions go on after the goal)."""
    obs, _ = env.reset(options={"env_code": env_code, "start_state": start_state})
    observations, rewards = [obs], []
    terminated = False
    for t, a in enumerate(actions):
        if terminated:
            raise ValueError(f"{what}: action {t + 1} of {len(actions)} comes after the goal")
        obs, r, terminated, _, _ = env.step(int(a))
        observations.append(obs)
        rewards.append(r)
    return Episode(env_code, dict(start_state), np.asarray(observations, dtype=np.int64),
                   np.asarray(actions, dtype=np.int64), np.asarray(rewards, dtype=float),
                   bool(terminated), metadata)


# ----------------------------------------------------------------- robot demonstrations
def candidate_episodes(domain: Any, *, profile: str = "default",
                       env_indices: Iterable[int] | None = None,
                       progress: bool = False) -> list[Episode]:
    """Every candidate demonstration of `domain` (each reachable state of each instance,
    followed optimally under w* as `cfteach.bec.demo_set` plans it); `env_indices` keeps
    only those instances; `progress` shows bars (on stderr) for planning and replaying."""
    from tqdm import tqdm

    from cfteach.bec.demos import demo_set

    with tqdm(total=None, desc="planning candidates", disable=not progress, leave=False):
        ds = demo_set(domain, profile)
    env = episode_env(domain, max(1, int(ds.length.max())) + 1)
    keep = None if env_indices is None else {int(i) for i in env_indices}
    out = []
    for d in tqdm(range(ds.D), desc="episodes", disable=not progress, leave=False):
        inst = ds.instance(d)
        if keep is not None and inst.index not in keep:
            continue
        acts = [int(a) for a in ds.actions[d, : ds.length[d]]]
        if not acts:
            continue
        meta = {"source": "candidate", "demo_index": d, "env_index": int(inst.index)}
        out.append(play(env, _bits(inst.env_code), inst.state_to_json(ds.start_state(d)),
                        acts, meta, f"candidate demonstration {d}"))
    return out


def curriculum_episodes(domain: Any, curriculum: dict[str, Any]) -> list[Episode]:
    """The demonstrations of one curriculum (`cfteach.curriculum/1`, docs/schemas.md)."""
    if curriculum.get("schema") != "cfteach.curriculum/1":
        raise ValueError(f"expected a cfteach.curriculum/1 file, got schema "
                         f"{curriculum.get('schema')!r}")
    if curriculum.get("domain") != domain.name:
        raise ValueError(f"the curriculum is for domain {curriculum.get('domain')!r}, "
                         f"not {domain.name!r}")
    names = list(domain.actions)
    demos = curriculum.get("demos") or []
    longest = max((len(d["actions"]) for d in demos), default=0)
    env = episode_env(domain, max(1, longest) + 1)
    out = []
    for k, d in enumerate(demos):
        inst = domain.instance(int(d["env_index"]))
        acts = [names.index(a) for a in d["actions"]]
        meta = {"source": "curriculum", "condition": curriculum.get("condition", ""),
                "demo_index": k, "env_index": int(inst.index)}
        ep = play(env, _bits(inst.env_code), d["start_state"], acts, meta,
                  f"curriculum demo {k}")
        _agree(ep.total_reward, d.get("reward"), f"curriculum demo {k}")
        out.append(ep)
    return out


def _agree(replayed: float, recorded: Any, what: str) -> None:
    if recorded is None or recorded == "":
        return
    if abs(replayed - float(recorded)) > REWARD_TOL:
        raise ValueError(f"{what}: replaying its actions gives reward {replayed!r}, the file "
                         f"says {float(recorded)!r}")


# --------------------------------------------------------------------- people's answers
def answer_episodes(domain: Any, study_dir: str | Path, export_dir: str | Path, *,
                    statuses: Iterable[str] | None = None) -> list[Episode]:
    """People's test answers for one domain: one episode per participant x test, read from a
    study folder (which test was where) and its export (`test_responses.csv`: the played
    `actions`; `participants.csv`: status). Each replay must give the exported reward."""
    import csv

    from cfteach.ecosystem.study_files import load_tests

    tests = load_tests(domain, study_dir)
    export_dir = Path(export_dir)
    status = _statuses(export_dir / "participants.csv")
    keep = None if statuses is None else set(statuses)
    path = export_dir / "test_responses.csv"
    if not path.is_file():
        raise ValueError(f"{path}: no such file (give the folder `cfteach study export` wrote)")
    with open(path, newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(f) if r.get("domain") == domain.name]
    names = list(domain.actions)
    longest = max((len(r["actions"].split()) for r in rows), default=0)
    env = episode_env(domain, max(1, longest) + 1)
    out = []
    for i, r in enumerate(rows):
        pid = r["participant_id"]
        if keep is not None and status.get(pid, "") not in keep:
            continue
        what = f"test_responses.csv row {i + 1} (participant {pid}, test {r['test_id']})"
        test = tests.get(r["test_id"])
        if test is None:
            raise ValueError(f"{what}: the study folder has no test {r['test_id']!r}")
        try:
            acts = [names.index(a) for a in r["actions"].split()]
        except ValueError:
            raise ValueError(f"{what}: unknown action in {r['actions']!r} "
                             f"(actions: {', '.join(names)})") from None
        if not acts:
            continue
        meta = {"source": "study", "participant_id": pid, "condition": r["condition"],
                "status": status.get(pid, ""), "test_id": r["test_id"],
                "difficulty": r["difficulty"], "domain_position": _int(r["domain_position"]),
                "trial_index": _int(r["trial_index"]), "optimal": _int(r["optimal"]),
                "optimal_reward": float(r["optimal_reward"]), "time_ms": _int(r["time_ms"]),
                "confidence": _int(r["confidence"]), "env_index": test.env_index}
        if "client_time_ms" in r:  # newer exports: the page's own clock as well
            meta["client_time_ms"] = _int(r["client_time_ms"])
        ep = play(env, test.env_code, test.start_state, acts, meta, what)
        _agree(ep.total_reward, r.get("reward"), what)
        out.append(ep)
    return out


def _int(x: str) -> int:
    return int(x) if x not in ("", None) else -1


def _statuses(path: Path) -> dict[str, str]:
    import csv

    if not path.is_file():
        return {}
    with open(path, newline="", encoding="utf-8") as f:
        return {r["participant_id"]: r.get("status", "") for r in csv.DictReader(f)}
