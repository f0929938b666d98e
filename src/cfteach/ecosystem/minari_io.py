"""Episodes to Minari datasets (Farama's offline-RL format) and back, locally only.

Each dataset holds one domain: its environment spec is the registered `cfteach/...` ID with
`observation="state"` and `env_code="random"`, so `dataset.recover_environment()` gives an env
whose `reset(options=episode_options)` restarts any episode (Minari stores the options as
episode metadata). Nothing is downloaded: datasets are written to and read from the Minari
root (`MINARI_DATASETS_PATH`, else `~/.minari/datasets`), or `root=` when given.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from cfteach.ecosystem.episodes import REWARD_TOL, Episode

_MISSING = ("minari is not installed: pip install 'cfteach[rl]' (or 'minari[hdf5]')")


def _minari() -> Any:
    try:
        import minari
    except ImportError:
        raise ImportError(_MISSING) from None
    return minari


@contextmanager
def minari_root(root: str | Path | None) -> Iterator[None]:
    """Point Minari at `root` for the duration (None: leave its own setting alone)."""
    if root is None:
        yield
        return
    old = os.environ.get("MINARI_DATASETS_PATH")
    os.environ["MINARI_DATASETS_PATH"] = str(Path(root).resolve())
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("MINARI_DATASETS_PATH", None)
        else:
            os.environ["MINARI_DATASETS_PATH"] = old


def env_spec(domain: Any, domain_arg: str | None, max_steps: int) -> Any:
    """The Gymnasium spec a dataset of `domain` records (built-in ID or the generic one)."""
    import gymnasium
    from gymnasium.envs.registration import EnvSpec

    from cfteach import gym as cgym

    eid = cgym.env_id(domain.name)
    kwargs: dict[str, Any] = {"observation": "state", "env_code": "random",
                              "max_steps": int(max_steps)}
    if eid == cgym.ENV_ID:
        kwargs["domain"] = domain_arg or domain.name
    base = gymnasium.spec(eid)
    return EnvSpec(id=eid, entry_point=base.entry_point, kwargs={**base.kwargs, **kwargs},
                   max_episode_steps=int(max_steps))


def write_dataset(episodes: Sequence[Episode], dataset_id: str, domain: Any, *,
                  domain_arg: str | None = None, root: str | Path | None = None,
                  description: str = "", author: str | None = None,
                  force: bool = False) -> Any:
    """Write `episodes` as Minari dataset `dataset_id` and return the opened dataset.

    `domain_arg` is how readers load a user domain (its file path); built-in domains need
    none. An existing dataset of that id is an error unless `force`.
    """
    if not episodes:
        raise ValueError(f"{dataset_id}: no episodes to write")
    minari = _minari()
    from minari.data_collector.episode_buffer import EpisodeBuffer

    from cfteach import gym as cgym

    longest = max(len(e.actions) for e in episodes)
    spec = env_spec(domain, domain_arg, max(cgym.MAX_EPISODE_STEPS, longest + 1))
    env = spec.make()
    buffers = [EpisodeBuffer(id=k, options=e.options, observations=list(e.observations),
                             actions=list(e.actions),
                             rewards=[float(r) for r in e.rewards],
                             terminations=[False] * (len(e.actions) - 1) + [e.terminated],
                             truncations=[False] * (len(e.actions) - 1) + [not e.terminated])
               for k, e in enumerate(episodes)]
    final_root = _root_path(root)
    target = final_root / dataset_id
    if (target / "data").exists() and not force:
        raise ValueError(f"dataset {dataset_id!r} exists already (--force / force=True "
                         "replaces it)")
    final_root.mkdir(parents=True, exist_ok=True)
    # Written in a hidden folder of the root (Minari lists no hidden folder) and moved into
    # place at the end: an interrupted export leaves no dataset, never a partial one.
    staging = Path(tempfile.mkdtemp(prefix=".cfteach-writing-", dir=final_root))
    try:
        with minari_root(staging):
            with warnings.catch_warnings():  # Minari's advice to name a code link and email
                warnings.filterwarnings("ignore", category=UserWarning, module="minari")
                ds = minari.create_dataset_from_buffers(
                    dataset_id, buffers, env=spec, eval_env=spec,
                    observation_space=env.observation_space, action_space=env.action_space,
                    algorithm_name="cfteach", author=author or "cfteach",
                    description=description or None, requirements=["cfteach"])
            ds.storage.update_episode_metadata([_attrs(e.metadata) for e in episodes],
                                               list(range(len(episodes))))
            del ds  # close its files before the move
        _move_into_place(staging / dataset_id, target, staging)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    ds = load_dataset(dataset_id, final_root)
    env.close()
    return ds


def _root_path(root: str | Path | None) -> Path:
    """The Minari root a dataset goes to: `root`, else Minari's own setting."""
    if root is not None:
        return Path(root).resolve()
    env = os.environ.get("MINARI_DATASETS_PATH")
    return Path(env).resolve() if env else Path.home() / ".minari" / "datasets"


def _move_into_place(written: Path, target: Path, staging: Path) -> None:
    """Rename the finished dataset to its place (an old one is moved aside first and
    deleted only once the new one is in)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    old = None
    if target.exists():
        old = staging / ".replaced"
        os.replace(target, old)
    os.replace(written, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def dataset_exists(dataset_id: str, root: str | Path | None = None) -> bool:
    """A local Minari dataset of that id exists (checked before any work)."""
    _minari()
    return (_root_path(root) / dataset_id / "data").exists()


def _attrs(meta: dict[str, Any]) -> dict[str, Any]:
    """Metadata as HDF5-attribute-safe values (no None)."""
    return {k: ("" if v is None else v) for k, v in meta.items()}


def load_dataset(dataset_id: str, root: str | Path | None = None) -> Any:
    """Open a local Minari dataset (never downloads)."""
    minari = _minari()
    from minari.storage.datasets_root_dir import get_dataset_path

    with minari_root(root):
        try:
            return minari.load_dataset(dataset_id, download=False)
        except FileNotFoundError:
            raise ValueError(f"no local Minari dataset {dataset_id!r} (looked in "
                             f"{get_dataset_path(dataset_id)})") from None


def episode_metadata(dataset: Any) -> list[dict[str, Any]]:
    """Per-episode metadata (reset options, participant, condition, ...) in episode order."""
    return list(dataset.storage.get_episode_metadata(dataset.episode_indices))


def check_replay(dataset: Any, progress: bool = False) -> int:
    """Replay every episode step by step in `dataset.recover_environment()` and compare
    observations, rewards and endings with the recorded ones; returns the episodes checked
    (ValueError names the first difference)."""
    env = dataset.recover_environment()
    metas = episode_metadata(dataset)
    from tqdm import tqdm

    n = 0
    for ep, meta in tqdm(zip(dataset.iterate_episodes(), metas, strict=True), total=len(metas),
                         desc="replaying", disable=not progress, leave=False):
        where = f"episode {ep.id}"
        obs, _ = env.reset(options=dict(meta["options"]))
        _same(obs, ep.observations[0], f"{where}: start observation")
        for t, a in enumerate(ep.actions):
            obs, r, term, trunc, _ = env.step(int(a))
            _same(obs, ep.observations[t + 1], f"{where} step {t + 1}: observation")
            if abs(r - float(ep.rewards[t])) > REWARD_TOL:
                raise ValueError(f"{where} step {t + 1}: reward {r!r}, recorded "
                                 f"{float(ep.rewards[t])!r}")
            if bool(term) != bool(ep.terminations[t]):
                raise ValueError(f"{where} step {t + 1}: terminated {term}, recorded "
                                 f"{bool(ep.terminations[t])}")
            if trunc and t + 1 < len(ep.actions):
                raise ValueError(f"{where} step {t + 1}: the environment truncates early")
        n += 1
    env.close()
    return n


def _same(a: Any, b: Any, what: str) -> None:
    if not np.array_equal(np.asarray(a), np.asarray(b)):
        raise ValueError(f"{what} {np.asarray(a).tolist()} differs from the recorded "
                         f"{np.asarray(b).tolist()}")
