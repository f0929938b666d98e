"""Tabular deterministic MDPs as numpy arrays; batched planning over instances x weights.

`compile_domain` turns a domain's instances into padded arrays (`MDPBatch`);
`value_iteration` solves all (instance, weight vector) pairs at once; `greedy_actions`,
`tied_actions`, `rollout_features` / `rollout_from` / `rollout` follow the reference's
policy and rollout rules; `best_tied_trajectories` / `best_tied_mu` (on chosen pairs) are
the "benefit of the doubt" counterfactual by DP; `best_tied_policy` its first actions
(optionally only among trajectories that reach the terminal), which simulated learners follow.
"""

from cfteach.mdp.arrays import MDPBatch, compile_domain, compile_instances
from cfteach.mdp.rollout import (
    Rollouts,
    Trajectory,
    replay,
    rollout,
    rollout_features,
    rollout_from,
)
from cfteach.mdp.tied import (
    BestTied,
    best_tied_mu,
    best_tied_policy,
    best_tied_trajectories,
    count_tied_trajectories,
)
from cfteach.mdp.vi import Values, greedy_actions, tied_actions, value_iteration

__all__ = ["BestTied", "MDPBatch", "Rollouts", "Trajectory", "Values", "best_tied_mu",
           "best_tied_policy", "best_tied_trajectories",
           "compile_domain", "compile_instances", "count_tied_trajectories", "greedy_actions",
           "replay", "rollout", "rollout_features", "rollout_from", "tied_actions",
           "value_iteration"]
