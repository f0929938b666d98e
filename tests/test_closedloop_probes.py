"""The teacher's probes are drawn as the post-tests are (rule "levels"); the rule before
("prior") stays for study files written with it."""

from __future__ import annotations

import numpy as np
import pytest

from cfteach import teaching
from cfteach.closedloop import TeacherSettings, build_pool
from cfteach.closedloop.probes import PROBE_RULES, lesson_blocked, probe_demos

N = TeacherSettings().n_probes


@pytest.fixture(scope="module", params=["delivery", "tiles"])
def material(request):
    cur = teaching.teach(request.param, "proposed")
    tests = teaching.select_tests(request.param, training=[cur])
    return tests, build_pool(request.param, held_out=tests)


def test_levels_probes_fall_in_the_post_tests_difficulty_levels(material):
    """Checked against `select_tests`' own clustering (its TestSet, made with the
    curriculum excluded): every probe lies in a cluster the post-tests are drawn from, about
    a third in each, and their mean overlap with the posterior is the post-tests' within
    0.1. The prior's rule put 34-39 of 48 probes in the easiest cluster, at 1.5 x the
    post-tests' mean overlap."""
    from cfteach.teaching.testsel import level_clusters

    tests, pool = material
    probes = probe_demos(pool, N)
    assert N - 3 <= len(probes) <= N
    assert not set(probes.tolist()) & set(pool.held_out)
    levels = [c for c in level_clusters(len(tests.cluster_centres)).values() if c is not None]
    counts = [int(np.sum(tests.clusters[probes] == c)) for c in levels]
    assert sum(counts) == len(probes)
    assert min(counts) >= len(probes) // 3 - 3
    held = np.array(sorted(pool.held_out))
    assert abs(tests.overlaps[probes].mean() - tests.overlaps[held].mean()) < 0.1
    before = probe_demos(pool, N, "prior")
    assert tests.overlaps[before].mean() - tests.overlaps[held].mean() > 0.3


def test_each_rule_has_its_own_probes_and_blocked_lessons(material):
    _, pool = material
    a, b = (probe_demos(pool, N, r) for r in PROBE_RULES)
    assert not np.array_equal(a, b)
    for rule, probes in zip(PROBE_RULES, (a, b), strict=True):
        assert lesson_blocked(pool, N, rule) == frozenset(pool.held_out) | set(probes.tolist())


def test_a_bad_rule_is_refused_before_any_work():
    with pytest.raises(ValueError, match="probes must be one of levels, prior"):
        TeacherSettings(probes="easy")
    with pytest.raises(ValueError, match="probe rule must be one of"):
        probe_demos(None, N, "easy")  # type: ignore[arg-type]


def test_a_study_file_without_the_rule_keeps_the_rule_it_was_written_with():
    from cfteach.study.live import settings_of

    stored = TeacherSettings().to_json()
    assert stored["probes"] == "levels"
    assert settings_of({"settings": stored}).probes == "levels"
    del stored["probes"]
    assert settings_of({"settings": stored}).probes == "prior"
