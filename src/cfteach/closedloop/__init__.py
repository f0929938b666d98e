"""Closed-loop teaching: demonstrations, diagnostic tests and feedback chosen one at a time
from a particle belief over the learner's reward weights (docs/closed-loop.md).

    from cfteach.closedloop import ClosedLoopTeacher, build_pool
    pool = build_pool("delivery", held_out=tests)   # tests: the post-teaching TestSet
    teacher = ClosedLoopTeacher(pool, seed=0)
    item = teacher.next(); teacher.observe({})      # a demonstration was shown

It sits on `teaching` (Algorithm 1's counterfactual rows, Algorithm 2's test constraints, the
tie-breaks) and below `simulate` and `study`, which both drive the same object.
"""

from cfteach.closedloop.belief import ParticleBelief
from cfteach.closedloop.noisy_belief import NoisyBelief
from cfteach.closedloop.pool import LessonPool, build_pool, held_out_demos
from cfteach.closedloop.settings import TeacherSettings
from cfteach.closedloop.teacher import ClosedLoopTeacher, Item

__all__ = ["ClosedLoopTeacher", "Item", "LessonPool", "NoisyBelief", "ParticleBelief",
           "TeacherSettings", "build_pool", "held_out_demos"]
