"""Test-suite wiring shared by every test file: the tiers of `scripts/test`.

Markers (registered in pyproject.toml) select the tiers: `--quick` runs
`not browser and not postgres and not slow`. Two things here keep that selection honest:

- So that a browser test can never slip into the quick tier unmarked, every test in a
  `*_browser.py` file, and every test that asks for the `browser` fixture (a launched
  Chromium), is marked `browser`.
- `SLOW` names the tests (by file and function; every parameter) that took 10 s or more in
  the quick tier (2 workers, measured on a shared 2-core machine at load 12-17, where 10 s
  is about 1.5 s of CPU), and the files whose module fixtures alone take that long (`*`).
  They are marked `slow` here rather than in each file, so that one measurement updates one
  list. A name that no longer matches a test of its file stops the run with one line
  (when whole files are collected), so the list cannot rot silently. Tests marked `slow` in
  their own file (R reference fits, pipelines) stay so; this list only adds.
- Files with browser or slow tests are collected first (`_long_files_first`), so that
  `--dist loadfile` starts them early rather than leaving one to run alone at the end.
"""

from __future__ import annotations

import pytest

BROWSER_FIXTURES = frozenset({"browser"})

SLOW: dict[str, frozenset[str] | str] = {
    # module fixtures that build a study export, datasets or teachers (10 s to 150 s loaded)
    "test_analysis_figures.py": "*",
    "test_analysis_glmm.py": "*",
    "test_analysis_pipeline.py": "*",
    "test_closedloop_noisy.py": "*",
    "test_ecosystem.py": "*",
    "test_parallel_teaching.py": "*",
    "test_simulate_closed_loop.py": "*",
    "test_study_fuzz.py": "*",
    **{f: frozenset(names.split()) for f, names in {
        "test_analysis_closed_loop.py": "test_analyze_reports_closed_loop_and_keeps_the_paper"
                                        "_analysis test_every_session_is_counted",
        "test_analysis_docs.py": "test_python_examples_run",
        "test_analysis_factorial.py": "test_results_and_skips",
        "test_analysis_ordinal.py": "test_in_results_and_skipped_without_confidence "
                                    "test_planted_mental_effort_and_confidence_effects",
        "test_analysis_power.py": "test_cli_power_writes_table_and_plot "
                                  "test_planted_effect_has_power_and_absent_one_does_not",
        "test_analysis_sensitivity.py": "test_sensitivity_variants_match_separate_runs",
        "test_analysis_validation.py": "test_cli_synthetic_pilots "
                                       "test_empty_confidence_skips_only_the_confidence_analyses "
                                       "test_pilot_exports_get_a_report "
                                       "test_reported_n_is_the_n_the_test_used",
        "test_bec.py": "test_human_trajectories_match_depth_first_enumeration "
                       "test_reference_values_match_for_random_models "
                       "test_teaching_with_four_features_is_reproducible_from_the_seed",
        "test_cli_errors.py": "test_study_init_with_force_replaces_the_study",
        "test_cli_grammar.py": "test_teach_show_names_the_masked_feature_as_the_legend_does",
        "test_closedloop_belief.py": "test_doc_example_runs",
        "test_closedloop_docs.py": "test_doc_examples_run test_pictures_script_draws_the_beliefs",
        "test_closedloop_teacher.py": "test_inattentive_learner_absorbs_about_half "
                                      "test_loop_structure "
                                      "test_noiseless_learners_end_with_w_star_in_their_belief "
                                      "test_same_seed_same_items_and_next_is_idempotent",
        "test_domains_actions.py": "test_taxi_one_step_constraints_against_replays "
                                   "test_taxi_policy_bec_is_the_original_two_constraints",
        "test_domains_compile.py": "test_step_before_the_states_are_known_and_off_the_"
                                   "reachable_set",
        "test_domains_selection.py": "test_export_minari_demos_with_envs "
                                     "test_teaching_on_every_env_equals_teaching_on_the_domain",
        "test_ecosystem_docs.py": "test_reading_answers_with_minari_and_converting_them_for_"
                                  "imitation test_the_irl_example_recovers_a_reward_whose_"
                                  "policy_matches_and_prints_as_shown",
        "test_geometry_highdim.py": "test_least_squares_redundancy_test_matches_one_lp_per_row",
        "test_geometry_region.py": "test_random_polygons_match_fan_of_lhuilier_triangles "
                                   "test_reduction_matches_reference_lp_method",
        "test_geometry_robustness.py": "test_interior_finder_agrees_with_lp_on_emptiness",
        "test_geometry_shared.py": "test_fractions_in_five_dims_match_brute_force_monte_carlo",
        "test_geometry_slice.py": "test_three_free_weights_estimate_and_reduction_against_a"
                                  "_grid",
        "test_parallel_docs.py": "test_doc_examples_run",
        "test_report.py": "test_every_image_and_link_of_the_report_resolves",
        "test_simulate_sweep.py": "test_other_seed_changes_answers_and_chunking_is_by_identity",
        "test_simulate_learners.py": "test_no_demonstrations_does_worse_than_a_curriculum",
        "test_study_api.py": "test_full_participant_and_export",
        "test_study_closed_loop.py": "test_closed_loop_session_items_and_export_replay "
                                     "test_init_refuses_bad_conditions "
                                     "test_paper_study_file_is_unchanged_by_default",
        "test_study_closed_loop_offpath.py": "test_decisions_run_in_worker_processes "
                                             "test_refused_answers_do_no_teacher_work "
                                             "test_two_servers_share_one_session_exactly_once",
        "test_study_docs.py": "test_cfteach_serve_starts_and_migrates test_doc_example_runs",
        "test_study_games.py": "test_abandoned_sessions_free_their_cell "
                               "test_assignment_balances_216_sessions",
        "test_study_identity.py": "test_study_init_writes_a_key_outside_the_version_and_keeps_it",
        "test_study_security.py": "test_chunked_40_mb_body_does_not_grow_the_server",
        "test_study_versions.py": "test_a_changed_study_file_keeps_serving_sessions_started_on_"
                                  "the_old_one test_sessions_on_an_unstored_study_file_block_a_"
                                  "restart_unless_new_version",
        "test_teaching.py": "test_default_profile_reaches_the_bec_despite_unbounded_models",
        "test_teaching_cli.py": "test_two_workers_write_the_one_process_json",
        "test_teaching_docs.py": "test_doc_examples_run",
        "test_teaching_known.py": "test_gains_are_ratios_of_slice_measures "
                                  "test_slice_pictures_draw_arcs_and_polygons "
                                  "test_teach_2021_taxi_baseline_known_step_ends_on_the_2021_"
                                  "policy_constraints test_tests_overlaps_are_slice_measures",
        "test_teaching_mask.py": "test_same_curriculum_and_log_as_checking_every_demo",
    }.items()},
}


def _long_files_first(items: list[pytest.Item]) -> None:
    """Files with browser or slow tests first, each file's tests kept together and in
    order: `--dist loadfile` hands files out in this order, so the long ones start early
    instead of one of them running alone at the end while the other workers idle."""
    rank: dict[str, int] = {}
    for item in items:
        long = item.get_closest_marker("browser") or item.get_closest_marker("slow")
        file = str(item.path)
        rank[file] = min(rank.get(file, 1), 0 if long else 1)
    items.sort(key=lambda item: rank[str(item.path)])  # stable: files stay in order


def _function(item: pytest.Item) -> str:
    return getattr(item, "originalname", None) or item.name.split("[")[0]


@pytest.hookimpl(tryfirst=True)  # before `-m` / `-k` deselect
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    seen: dict[str, set[str]] = {}
    for item in items:
        file, name = item.path.name, _function(item)
        seen.setdefault(file, set()).add(name)
        browser_file = file.endswith("_browser.py")
        uses_browser = BROWSER_FIXTURES & set(getattr(item, "fixturenames", ()))
        if (browser_file or uses_browser) and item.get_closest_marker("browser") is None:
            item.add_marker(pytest.mark.browser)
        listed = SLOW.get(file)
        if listed is not None and (listed == "*" or name in listed):
            if item.get_closest_marker("slow") is None:
                item.add_marker(pytest.mark.slow)
    _long_files_first(items)
    if any("::" in str(a) for a in config.args):
        return  # only some tests of a file were collected: nothing to compare with
    stale = [f"{f}::{n}" for f, names in SLOW.items() if f in seen and names != "*"
             for n in sorted(names) if n not in seen[f]]
    if stale:
        raise pytest.UsageError(f"tests/conftest.py SLOW names tests that do not exist: "
                                f"{', '.join(stale)}")
