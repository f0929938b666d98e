"""cfteach: teach people a robot's decision making through well-chosen demonstrations.

Implements Lee, Admoni & Simmons, *Reasoning about Counterfactuals to Improve Human
Inverse Reinforcement Learning* (IROS 2022), and goes beyond it. Data flows one way:
domain -> MDPs -> demonstrations -> constraints -> beliefs -> curricula/tests ->
study -> analysis (see docs/architecture.md).
"""

__version__ = "0.1.0"
