"""How big a domain is, and what teaching it will cost, before anything is computed.

Planning works on every candidate demonstration at once (arrays of instances x padded
states x actions), so a domain file that looks small (a 30 x 30 grid, 9 variant bits) can
need minutes and many gigabytes. `estimate_size` counts instances exactly, counts the
reachable states of a sample of instances (or bounds them when even one instance is too
big to enumerate quickly), and applies a model measured on this code
(bench/teach_size_model.py) to predict one `teach` run's time and peak memory.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from cfteach.domains.model import Domain

__all__ = ["SizeEstimate", "available_memory", "estimate_size", "human_bytes",
           "human_seconds", "shrink_advice"]

#: Instances whose states are enumerated for the estimate (all of them when there are fewer).
SAMPLE_INSTANCES = 8
#: Above this many possible states per instance the count is bounded, not enumerated.
ENUMERATE_LIMIT = 50_000
#: Count every instance's states (an exact answer) when at most this many in all.
EXACT_LIMIT = 300_000

# Measured model of one `cfteach teach --condition proposed` run (default settings),
# fitted by bench/teach_size_model.py on random domains (3 features, 6 actions) of 800 to
# 87 000 padded states, N = instances x (most states of an instance + 1):
# memory = 90 MB + 313 B x N^1.41, time = 0.5 s + 5.8e-7 s x N^1.7 (within about 30% on
# the measured points: 8x8/16 instances 0.2 s 91 MB, 12x12/64 2.6 s 241 MB, 16x16/128 21 s
# 670 MB, 20x20/256 145 s 2.97 GB, on one core of a shared 2-core machine).
MEM_BASE_BYTES = 90e6
MEM_COEF = 313.0
MEM_EXPONENT = 1.41
TIME_BASE_SECONDS = 0.5
TIME_COEF = 5.8e-7
TIME_EXPONENT = 1.7


@dataclass(frozen=True)
class SizeEstimate:
    """Counts and predicted cost of a domain (see the module docstring)."""

    instances: int
    states_max: int  # most reachable non-terminal states of one instance
    demonstrations: int  # candidate demonstrations = reachable non-terminal states, summed
    exact: bool  # counted over every instance (else estimated from a sample or a bound)
    teach_seconds: float
    teach_peak_bytes: float

    @property
    def padded_states(self) -> int:
        return self.instances * (self.states_max + 1)

    def lines(self) -> list[str]:
        """Human-readable lines for `cfteach check`."""
        approx = "" if self.exact else "about "
        return [
            f"instances: {self.instances}",
            f"states per instance: {approx}up to {self.states_max}",
            f"demonstrations (candidates): {approx}{self.demonstrations}",
            f"teach (one condition), estimate: {human_seconds(self.teach_seconds)}, "
            f"peak memory {human_bytes(self.teach_peak_bytes)}",
        ]


def human_bytes(n: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} B"


def human_seconds(s: float) -> str:
    if s < 60:
        return f"{s:.0f} s" if s >= 1 else "< 1 s"
    if s < 3600:
        return f"{s / 60:.1f} min"
    return f"{s / 3600:.1f} h"


def _state_bound(dom: Domain) -> int:
    """An upper bound on one instance's states: agent cells x cargo x consumables."""
    spec = dom.spec
    cells = spec.width * spec.height - len(spec.walls)
    n = cells
    if spec.cargo is not None:
        n *= cells + 1  # cargo on any free cell, or held (same cell as the agent)
    return n * 2 ** len(spec.consumables)


def estimate_size(dom: Domain, sample: int = SAMPLE_INSTANCES, seed: int = 0) -> SizeEstimate:
    """Instances, states and demonstrations of `dom`, and the predicted cost of `teach`."""
    insts = dom.instances()  # a `--envs` subset counts only its own environments
    n_inst = len(insts)
    bound = _state_bound(dom)
    if bound > ENUMERATE_LIMIT:
        per = [bound]
        exact = False
    else:
        if n_inst <= sample or n_inst * bound <= EXACT_LIMIT:
            pos = list(range(n_inst))
        else:  # the first and last instances, and random ones between
            rng = np.random.default_rng(seed)
            pos = sorted({0, n_inst - 1, *(int(i) for i in rng.integers(0, n_inst, sample - 2))})
        dom.prefetch_states([insts[p].index for p in pos])
        per = [len(insts[p].states()) for p in pos]
        exact = len(pos) == n_inst
    s_max = max(per)
    demos = sum(per) if exact else int(round(float(np.mean(per)) * n_inst))
    padded = n_inst * (s_max + 1)
    scale = len(dom.actions) * dom.n_features / 18  # the model was measured at A x F = 18
    return SizeEstimate(
        instances=n_inst, states_max=s_max, demonstrations=demos, exact=exact,
        teach_seconds=TIME_BASE_SECONDS + TIME_COEF * (padded * scale) ** TIME_EXPONENT,
        teach_peak_bytes=MEM_BASE_BYTES + MEM_COEF * (padded * scale) ** MEM_EXPONENT,
    )


def available_memory() -> float | None:
    """Bytes of memory available to a new computation (MemAvailable), None if unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def shrink_advice(dom: Domain, est: SizeEstimate) -> str:
    """What to make smaller, naming the domain's own numbers."""
    tips = []
    if dom.n_bits > 3:
        tips.append(f"fewer variant bits ({dom.n_bits} bits = {est.instances} instances; "
                    "each bit removed halves the work)")
    tips.append(f"a smaller grid ({dom.width} x {dom.height})")
    if dom.spec.cargo is not None:
        tips.append("no cargo (it multiplies the states by the free cells)")
    return "make the domain smaller: " + ", ".join(tips)
