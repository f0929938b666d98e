"""Simulated study exports with planted effects, for demos and for testing the statistics.

The generator follows the study's design (4 conditions x 6 domain orders x 3 test sets,
3 domains x 6 tests, two Likert items per domain, one row per demonstration viewed) and
writes exactly the export format, so the same loader and pipeline read it. Correctness is
drawn from a logistic model with a random intercept per participant:

    logit P(optimal) = centre + difficulty_effect * dev[difficulty] + ability_i
                       + domain shift + interaction * counterfactual * sign[difficulty]
                       + feature_effect * feature_scaffolding

where `dev` are the paper's observed means (0.86, 0.71, 0.40 for low/medium/high) turned into
centred logits and `sign` is -1/0/+1 for low/medium/high: counterfactual scaffolding helps on
hard tests and hurts on easy ones, the interaction the paper reports (H2). Two more terms,
off by default, plant what only the full 2 x 2 x 3 model can see:
`cf_fs_interaction * (2cf - 1)(2fs - 1)` (a crossover: no marginal effect of either factor)
and `proposed_interaction * cf * fs * sign[difficulty]` (a difficulty effect that only the
two scaffoldings together have: a three-way interaction, which the paper's separate models
report as cf x difficulty and fs x difficulty).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
import pandas as pd

from cfteach.analysis.io import CF_CONDITIONS, CONDITIONS, DIFFICULTIES, FS_CONDITIONS, StudyExport

DOMAINS = ("delivery", "tiles", "skateboard")
DEMOS_PER_DOMAIN = {"delivery": 5, "tiles": 5, "skateboard": 7}
ORDERS = tuple(itertools.permutations(DOMAINS))
ACTION_NAMES = ("up", "down", "left", "right", "pickup", "dropoff")
_PAPER_MEANS = np.array([0.86, 0.71, 0.40])
_LOGITS = np.log(_PAPER_MEANS / (1 - _PAPER_MEANS))
CENTRE = float(_LOGITS.mean())
DEV = _LOGITS - _LOGITS.mean()
SIGN = np.array([-1.0, 0.0, 1.0])
DOMAIN_SHIFT = {"delivery": 0.0, "tiles": 0.3, "skateboard": -0.3}
OVERLAP_RANGE = {"low": (0.7, 0.95), "medium": (0.4, 0.6), "high": (0.05, 0.25)}


@dataclass(frozen=True)
class SyntheticConfig:
    """Knobs of the simulated study; every default plants the paper's direction of effects."""

    n_participants: int = 216
    seed: int = 0
    difficulty_effect: float = 1.0  # multiplies the paper's difficulty spread; 0 = no effect
    interaction: float = 0.35  # logit shift of counterfactual conditions, +high / -low
    feature_effect: float = 0.0
    cf_fs_interaction: float = 0.0  # logit x (+1 same scaffolding / -1 one of the two)
    proposed_interaction: float = 0.0  # logit x (-1, 0, +1)[difficulty], proposed only
    subject_sd: float = 0.6  # SD of the participants' random intercepts (logit)
    effort_cf: float = 0.5  # extra mental effort (Likert points) with counterfactuals
    replay_cf: float = 0.08  # extra expected replays per demonstration with counterfactuals
    time_cf_ratio: float = 1.18  # test time ratio counterfactual / not
    n_screened_out: int | None = None  # default: 5% of n_participants
    n_abandoned: int | None = None  # default: 3% of n_participants
    n_preview: int = 1
    n_outliers: int | None = None  # far worse than everyone else; default min(2, N // 10)

    def __post_init__(self) -> None:
        if self.n_participants < 1:
            raise ValueError(f"n_participants must be at least 1, got {self.n_participants}")
        for name in ("n_screened_out", "n_abandoned", "n_preview", "n_outliers"):
            v = getattr(self, name)
            if v is not None and v < 0:
                raise ValueError(f"{name} must be >= 0, got {v}")
        if self.n_outliers is not None and self.n_outliers > self.n_participants:
            raise ValueError("n_outliers cannot exceed n_participants")

    @property
    def outliers(self) -> int:
        """The number of planted outliers (a pilot of 1-9 participants gets none)."""
        return min(2, self.n_participants // 10) if self.n_outliers is None else self.n_outliers


def _hex(rng: np.random.Generator, n: int) -> str:
    return "".join("0123456789abcdef"[i] for i in rng.integers(0, 16, n))


def _items(rng: np.random.Generator) -> pd.DataFrame:
    """The study's test environments: domain x difficulty x test set x {a, b}."""
    rows = []
    for dom in DOMAINS:
        for diff in DIFFICULTIES:
            lo, hi = OVERLAP_RANGE[diff]
            for s in range(3):
                for ab in "ab":
                    length = int(rng.integers(4, 15))
                    rows.append(
                        {
                            "domain": dom,
                            "difficulty": diff,
                            "test_set": s,
                            "test_id": f"{dom}-{diff}-{s}{ab}",
                            "overlap": round(float(rng.uniform(lo, hi)), 4),
                            "optimal_length": length,
                            "optimal_reward": -round(0.12 * length + rng.uniform(0, 0.5), 3),
                            "optimal_actions": " ".join(rng.choice(ACTION_NAMES[:4], length)),
                        }
                    )
    return pd.DataFrame(rows)


def generate(config: SyntheticConfig | None = None) -> StudyExport:
    """Simulate a study export; the same config (seed included) gives the same export."""
    cfg = config or SyntheticConfig()
    rng = np.random.default_rng(cfg.seed)
    items = _items(np.random.default_rng([cfg.seed, 1]))
    by_set: dict[tuple[Any, Any], list] = {}  # (domain, test_set) as itertuples gives them
    for it in items.itertuples(index=False):
        by_set.setdefault((it.domain, it.test_set), []).append(it)
    n = cfg.n_participants
    n_screened = round(0.05 * n) if cfg.n_screened_out is None else cfg.n_screened_out
    n_abandoned = round(0.03 * n) if cfg.n_abandoned is None else cfg.n_abandoned
    kinds = (
        ["completed"] * n
        + ["screened_out"] * n_screened
        + ["abandoned"] * n_abandoned
        + ["preview"] * cfg.n_preview
    )
    outliers = set(rng.choice(n, cfg.outliers, replace=False).tolist()) if n else set()
    order = rng.permutation(len(kinds))  # interleave kinds in arrival order
    t0 = datetime(2026, 1, 12, 14, 0, tzinfo=UTC)
    parts, tests, likert, demos = [], [], [], []
    for arrival, k in enumerate(order):
        kind = kinds[k]
        cell = int(k) % 72 if kind == "completed" else int(rng.integers(72))
        cond = CONDITIONS[cell % 4]
        dom_order = ORDERS[(cell // 4) % 6]
        test_set = cell // 24
        cf, fs = int(cond in CF_CONDITIONS), int(cond in FS_CONDITIONS)
        pid = _hex(rng, 12)
        started = t0 + timedelta(minutes=7 * arrival + float(rng.uniform(0, 5)))
        duration = timedelta(minutes=float(rng.uniform(8, 30)))
        status = "completed" if kind == "preview" else kind
        parts.append(
            {
                "participant_id": pid,
                "prolific_pid": _hex(rng, 24),
                "study_id": "synthetic-study",
                "session_id": _hex(rng, 24),
                "condition": cond,
                "counterfactual": cf,
                "feature_scaffolding": fs,
                "domain_order": ";".join(dom_order),
                "test_set": test_set,
                "status": status,
                "is_preview": int(kind == "preview"),
                "started_at": started.isoformat().replace("+00:00", "Z"),
                "completed_at": (started + duration).isoformat().replace("+00:00", "Z")
                if status == "completed"
                else None,
                "practice_attempts": 3
                if kind == "screened_out"
                else int(rng.choice([1, 2, 3], p=[0.7, 0.22, 0.08])),
                "age": int(np.clip(round(rng.normal(28.4, 9.5)), 18, 69)),
                "gender": rng.choice(["male", "female", "non-binary"], p=[0.67, 0.32, 0.01]),
                "education": rng.choice(["high school", "bachelor", "master", "doctorate"]),
                "study_version": "synthetic",
            }
        )
        if kind == "screened_out":
            continue
        ability = rng.normal(0, cfg.subject_sd) - (6.0 if k in outliers else 0.0)
        n_domains = int(rng.integers(1, 3)) if kind == "abandoned" else 3
        for pos, dom in enumerate(dom_order[:n_domains], start=1):
            for j in range(DEMOS_PER_DOMAIN[dom]):
                replays = int(rng.poisson(0.15 + cfg.replay_cf * cf))
                length_ms = 6000 + 700 * j
                demos.append(
                    {
                        "participant_id": pid,
                        "condition": cond,
                        "domain": dom,
                        "demo_index": j,
                        "plays_completed": 1 + replays,
                        "replays": replays,
                        "watch_ms": int(length_ms * (1 + replays) + rng.integers(0, 800)),
                    }
                )
                demos[-1]["client_watch_ms"] = demos[-1]["watch_ms"]
            base_inf = 3.3 - 0.2 * cf
            base_eff = 2.4 + cfg.effort_cf * cf
            likert.append(
                {
                    "participant_id": pid,
                    "condition": cond,
                    "domain": dom,
                    "domain_position": pos,
                    "item": "informativeness",
                    "value": int(np.clip(round(rng.normal(base_inf, 0.9)), 1, 5)),
                }
            )
            likert.append(
                {
                    "participant_id": pid,
                    "condition": cond,
                    "domain": dom,
                    "domain_position": pos,
                    "item": "mental_effort",
                    "value": int(np.clip(round(rng.normal(base_eff, 0.9)), 1, 5)),
                }
            )
            dom_items = by_set[(dom, test_set)]
            n_tests = int(rng.integers(1, 6)) if (kind == "abandoned" and pos == n_domains) else 6
            shown = [dom_items[i] for i in rng.permutation(len(dom_items))[:n_tests]]
            m = len(shown)
            d_idx = np.array([DIFFICULTIES.index(it.difficulty) for it in shown], dtype=int)
            logit = (
                CENTRE
                + cfg.difficulty_effect * DEV[d_idx]
                + ability
                + DOMAIN_SHIFT[dom]
                + cfg.interaction * cf * SIGN[d_idx]
                + cfg.feature_effect * fs
                + cfg.cf_fs_interaction * (2 * cf - 1) * (2 * fs - 1)
                + cfg.proposed_interaction * cf * fs * SIGN[d_idx]
            )
            correct = rng.random(m) < 1 / (1 + np.exp(-logit))
            gaps = rng.gamma(2.0, 0.12, m) * (8.0 if k in outliers else 1.0) + 0.02
            extra = rng.integers(0, 5, m)
            secs_per_step = np.exp(
                rng.normal(np.log(2.49) + np.log(cfg.time_cf_ratio) * cf, 0.35, m)
            )
            conf = np.clip(
                np.round(3.4 - 0.3 * d_idx + 0.4 * correct + rng.normal(0, 1.1, m)), 1, 5
            )
            for trial, it in enumerate(shown, start=1):
                i = trial - 1
                if correct[i]:
                    reward, actions = it.optimal_reward, it.optimal_actions
                else:
                    reward = round(it.optimal_reward - float(gaps[i]), 3)
                    n_act = it.optimal_length + int(extra[i])
                    actions = " ".join(rng.choice(ACTION_NAMES, n_act))
                tests.append(
                    {
                        "participant_id": pid,
                        "condition": cond,
                        "domain": dom,
                        "domain_position": pos,
                        "test_id": it.test_id,
                        "difficulty": it.difficulty,
                        "overlap": it.overlap,
                        "trial_index": trial,
                        "actions": actions,
                        "n_actions": len(actions.split()),
                        "reward": reward,
                        "optimal_reward": it.optimal_reward,
                        "optimal": int(correct[i]),
                        "optimal_length": it.optimal_length,
                        "time_ms": int(secs_per_step[i] * it.optimal_length * 1000),
                        "confidence": int(conf[i]),
                    }
                )
                tests[-1]["client_time_ms"] = tests[-1]["time_ms"]
    return StudyExport(
        pd.DataFrame(parts),
        pd.DataFrame(tests),
        pd.DataFrame(likert),
        pd.DataFrame(demos),
    )
