"""The closed-loop teacher's backbone: an open-loop curriculum every session covers in full.

The backbone is why closed loop never teaches *less* than the open-loop curriculum
(docs/closed-loop.md, "The conversation"); these rules keep that true for a learner who
keeps failing, whose remedial lessons would otherwise fill the item budget first.
"""

from __future__ import annotations

from collections.abc import Sequence, Set

from cfteach.closedloop.items import Item
from cfteach.closedloop.pool import LessonPool

#: Items a lesson may cost: the lesson, its diagnostic test and the feedback on a failure.
ITEMS_PER_LESSON = 3


def lessons(pool: LessonPool, no_lesson: Set[int]) -> list[int]:
    """The pool's backbone as lessons a teacher may show: a demo whose start is a
    post-test's or a probe's (`no_lesson`) is replaced by another demo with the same
    constraints, or dropped when there is none (it would show a test's answer)."""
    out = []
    for d in pool.backbone:
        if d in no_lesson:
            s = int(pool.lessons.slot[d])
            same: list[int] = pool.lessons.members[s].tolist() if s >= 0 else []
            alt = [int(m) for m in same if int(m) not in no_lesson]
            if not alt:
                continue
            d = alt[0]
        out.append(d)
    return out


def remaining(items: Sequence[Item], backbone: Sequence[int]) -> int:
    """Backbone lessons not yet shown."""
    return max(len(backbone) - sum(it.purpose == "backbone" for it in items), 0)


def next_lesson(items: Sequence[Item], backbone: Sequence[int], blocked: set[int]
                ) -> Item | None:
    """The next backbone lesson not yet shown (None when all are shown, or when it is
    `blocked`: it would repeat a demonstration more than `max_repeat` times in a row)."""
    k = len(backbone) - remaining(items, backbone)
    if k >= len(backbone) or backbone[k] in blocked:
        return None
    return Item(len(items), "demonstration", "backbone", backbone[k])


def may_remediate(items: Sequence[Item], backbone: Sequence[int], failed: Item,
                  max_items: int) -> bool:
    """Whether a remedial lesson for test `failed` may come now. Always once the backbone
    is shown. Before: not for a failed test about a remedial lesson (one detour per
    backbone lesson, not a chain), and only while the items left after it still hold
    the remaining backbone lessons with their tests and feedback."""
    left = remaining(items, backbone)
    if left == 0:
        return True
    about = items[failed.about] if failed.about is not None else None
    if about is not None and about.purpose == "remedial":
        return False
    return max_items - len(items) - ITEMS_PER_LESSON >= ITEMS_PER_LESSON * left
