"""Simulated human learners: compare teaching conditions in minutes before a human study.

Learner models (docs/simulate.md): `counterfactual` (the paper's model of the human: the
belief is the region cut by the counterfactual constraints the learner forms against its
own sampled beliefs), `irl` (standard IRL: one-action-deviation constraints), `noisy`
(few counterfactuals per demonstration, Boltzmann-rational test answers). Test answers are
scored exactly as the study scores people (`cfteach.simulate.scoring`).
"""

from cfteach.simulate.scoring import is_optimal, score_answers

__all__ = ["is_optimal", "score_answers"]
