"""`TeacherSettings`: how the closed-loop teacher models the learner and picks items.

Plain data with defaults (a study file stores them with `to_json`; `study.live.settings_of`
reads them back), checked on construction so a bad value fails before any work.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from cfteach.closedloop.noisy_params import CONFUSED, DISENGAGED, LAPSE, RATIONALITY, UPTAKE
from cfteach.closedloop.probes import PROBE_RULES
from cfteach.closedloop.since import CONFUSION_MODELS

MODELS = ("noisy", "fixed")
_GRIDS = ("zpd_band", "rationality", "uptake", "disengaged", "confused")


@dataclass(frozen=True)
class TeacherSettings:
    """How the closed-loop teacher models the learner and picks items (docs/closed-loop.md)."""

    n_particles: int = 1000
    p_learn: float = 0.8          # model "fixed": chance a shown demonstration is absorbed
    temperature: float = 0.5      # model "fixed": Boltzmann temperature of test answers
    zpd_proportion: float = 1.0   # target cut, as a share of the largest (paper's cf: 0.7)
    zpd_band: tuple[float, float] = (0.3, 1.0)  # admissible cuts, as shares of the largest
    min_gain: float = 0.02        # a lesson cutting less belief than this teaches nothing
    stop_threshold: float = 0.95  # belief mass inside the probes' regions that ends teaching
    remedial_threshold: float = 0.8  # below this P(optimal) on a failed test: remedial lesson
    min_discrimination: float = 0.05  # a diagnostic test must split the particles this much
    max_items: int = 40           # demonstrations + tests + feedback
    model: str = "noisy"          # "noisy": rationality, uptake inferred; "fixed": v1 model
    rationality: tuple[float, ...] = RATIONALITY  # model "noisy": grid of beta
    uptake: tuple[float, ...] = UPTAKE            # model "noisy": grid of demo uptake
    disengaged: tuple[float, ...] = DISENGAGED    # model "noisy": grid of P(random answer)
    confused: tuple[float, ...] = CONFUSED        # model "noisy", confusion "grid": grid of
    #                          P(attempt planned under weights drawn from the belief then)
    confusion: str = "since"      # model "noisy": "since", that share is 1 - (1 - uptake)^k
    #                               for an answer k demonstrations back; "grid": `confused`
    lapse: float = LAPSE          # model "noisy": chance of a random move at any step
    test_every: int = 3           # after the first test, a test at least every this many items
    max_repeat: int = 2           # the same demonstration at most this many times in a row
    n_probes: int = 48            # the teacher's own probe tests (never the post-tests)
    probes: str = "levels"        # how they are drawn: "levels", as the post-tests are
    #                               (Algorithm 2's difficulty levels); "prior": the rule before
    min_passes: int = 2           # stop only after this many passed tests in a row
    belief_models: int = 0        # human models drawn from the belief after each test answer
    #                               (their counterfactual rows join the pool's; 0: none)

    def __post_init__(self) -> None:
        for name in _GRIDS:  # lists (from JSON) become tuples
            object.__setattr__(self, name, tuple(float(x) for x in getattr(self, name)))
        checks = [
            ("n_particles", isinstance(self.n_particles, int) and self.n_particles >= 10,
             "an integer >= 10"),
            ("p_learn", 0 < self.p_learn < 1, "in (0, 1)"),
            ("temperature", self.temperature > 0, "> 0"),
            ("zpd_proportion", 0 < self.zpd_proportion <= 1, "in (0, 1]"),
            ("zpd_band", len(self.zpd_band) == 2
             and 0 <= self.zpd_band[0] <= self.zpd_proportion <= self.zpd_band[1] <= 1,
             "(low, high) with 0 <= low <= zpd_proportion <= high <= 1"),
            ("min_gain", 0 <= self.min_gain < 1, "in [0, 1)"),
            ("stop_threshold", 0 < self.stop_threshold <= 1, "in (0, 1]"),
            ("remedial_threshold", 0 <= self.remedial_threshold <= 1, "in [0, 1]"),
            ("min_discrimination", 0 <= self.min_discrimination < 1, "in [0, 1)"),
            ("max_items", isinstance(self.max_items, int) and self.max_items >= 1,
             "an integer >= 1"),
            ("model", self.model in MODELS, f"one of {', '.join(MODELS)}"),
            ("rationality", len(self.rationality) >= 1 and all(0 < b < float("inf")
                                                               for b in self.rationality),
             "one or more positive numbers"),
            ("uptake", len(self.uptake) >= 1 and all(0 < u < 1 for u in self.uptake),
             "one or more numbers in (0, 1)"),
            ("disengaged", len(self.disengaged) >= 1
             and all(0 < x < 1 for x in self.disengaged), "one or more numbers in (0, 1)"),
            ("confused", len(self.confused) >= 1
             and all(0 <= x < 1 for x in self.confused), "one or more numbers in [0, 1)"),
            ("lapse", 0 <= self.lapse < 1, "in [0, 1)"),
            ("test_every", isinstance(self.test_every, int) and self.test_every >= 1,
             "an integer >= 1"),
            ("max_repeat", isinstance(self.max_repeat, int) and self.max_repeat >= 1,
             "an integer >= 1"),
            ("confusion", self.confusion in CONFUSION_MODELS,
             f"one of {', '.join(CONFUSION_MODELS)}"),
            ("probes", self.probes in PROBE_RULES, f"one of {', '.join(PROBE_RULES)}"),
            ("min_passes", isinstance(self.min_passes, int) and self.min_passes >= 0,
             "an integer >= 0"),
            ("n_probes", isinstance(self.n_probes, int) and self.n_probes >= 1,
             "an integer >= 1"),
            ("belief_models", isinstance(self.belief_models, int)
             and not isinstance(self.belief_models, bool) and 0 <= self.belief_models <= 64,
             "an integer in 0..64"),
        ]
        for name, ok, want in checks:
            if not ok:
                raise ValueError(f"closed-loop setting {name} must be {want}, "
                                 f"got {getattr(self, name)!r}")

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        for name in _GRIDS:
            out[name] = list(getattr(self, name))
        return out
