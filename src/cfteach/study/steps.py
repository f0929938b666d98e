"""The server-driven step machine: the ordered list of pages one participant goes through.

The list is a pure function of the study and the session's assignment (condition, domain
order, test set, seed), so it is never stored and a reload lands on exactly the same page.
"""

from __future__ import annotations

import random

#: Slack, in ms, allowed below a demonstration's replay length (network and timer jitter;
#: the page's own replay runs one step longer than the check asks for).
DEMO_TOLERANCE_MS = 250


def demo_required_ms(n_actions: int, step_ms: int) -> int:
    """Server-measured play time a demonstration of `n_actions` steps needs to count as
    watched to the end: its replay length (`n_actions` x `step_ms`) minus the tolerance."""
    return max(0, n_actions * step_ms - DEMO_TOLERANCE_MS)


def shuffled_tests(seed: int, domain: str, n: int) -> list[int]:
    """Shuffled test positions for one domain (seeded per session, so it is reproducible)."""
    order = list(range(n))
    random.Random(f"{seed}:{domain}").shuffle(order)
    return order


def build_steps(study: dict, domain_order: list[str], test_set: int, seed: int,
                condition: str | None = None) -> list[dict]:
    """The session's pages. A ``closed_loop`` session's teaching phase is one
    ``closed_loop`` step per domain, whose items the server's teacher decides one at a time
    (`cfteach.study.live`); every other page is the same for all conditions."""
    teach = "closed_loop" if condition == "closed_loop" else "demos"
    steps: list[dict] = [{"kind": "consent"}, {"kind": "instructions"}, {"kind": "free_play"},
                         {"kind": "practice"}, {"kind": "post_practice"}]
    for pos, dom in enumerate(domain_order, start=1):
        base = {"domain": dom, "position": pos}
        steps += [{"kind": "domain_intro", **base}, {"kind": teach, **base},
                  {"kind": "survey", **base}]
        n = len(study["tests"][dom][test_set])
        for trial, t in enumerate(shuffled_tests(seed, dom, n), start=1):
            steps.append({"kind": "test", **base, "trial": trial, "test_index": t})
        steps.append({"kind": "feedback", **base, "last": pos == len(domain_order)})
    steps += [{"kind": "demographics"}, {"kind": "complete"}]
    return steps


#: Event types a participant may send on each kind of step (plus `page_load` anywhere).
ALLOWED = {
    "consent": {"consent", "decline"},
    "instructions": {"continue"},
    "free_play": {"continue"},
    "practice": {"practice_attempt"},
    "post_practice": {"continue"},
    "domain_intro": {"continue"},
    "demos": {"demo_play_start", "demo_play_end", "continue"},
    "closed_loop": {"demo_play_start", "demo_play_end", "item_done"},
    "survey": {"likert"},
    "test": {"test_response"},
    "feedback": {"continue"},
    "demographics": {"demographics"},
    "complete": set(),
}
