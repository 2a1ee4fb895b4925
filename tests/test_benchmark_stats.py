"""The benchmark report's statistics on hand-computed cases: rliable's probability of
improvement (ties one half) and the Target section's verdict from the numbers."""

from __future__ import annotations

import pytest

from accd_gym.evals.benchmark import choose_method, choose_run, probability_of_improvement, report_markdown, target as _target


def _validation_as_held_out(eps):
    """Validation records equal to the held-out ones, grouped by method (run names
    ``<tier>_<method>_seed<k>``): for tests of the verdict, not of the choice."""
    out = {}
    for tier, runs in eps.items():
        for name, captured in runs.items():
            if name != "lqr":
                method = name[len(tier) + 1:].rsplit("_seed", 1)[0]
                out.setdefault(tier, {}).setdefault(method, {})[name] = captured
    return out


def target(tiers, eps, validation=None, **kw):
    return _target(tiers, eps, _validation_as_held_out(eps) if validation is None else validation, **kw)


def test_probability_of_improvement_counts_ties_as_one_half():
    # pairs (x, y): 0.9 beats 0.8 and 0.85; 0.8 ties 0.8 (1/2) and loses to 0.85; 0.7 loses both
    # -> (2 + 0.5 + 0 + 0) / 6
    assert probability_of_improvement([0.9, 0.8, 0.7], [0.8, 0.85]) == pytest.approx(2.5 / 6)
    assert probability_of_improvement([0.93, 0.92, 0.92], [0.92]) == pytest.approx((1 + 0.5 + 0.5) / 3)
    assert probability_of_improvement([0.5], [0.5]) == 0.5
    with pytest.raises(ValueError, match="runs on both sides"):
        probability_of_improvement([], [0.5])


def _tiers(rates, lqr_rate, ci):
    return {"policies": {"ppo": {"kind": "learned", "rates": rates, "iqm": sum(rates) / len(rates), "ci95": ci},
                         "lqr": {"kind": "classical", "rate": lqr_rate}}}


def test_target_is_read_from_the_numbers():
    lqr = [True] * 90 + [False] * 10
    better = [True] * 98 + [False] * 2          # 8 gained, 0 lost: p = 2 * 0.5**8 < 0.05
    same = list(lqr)
    tiers = {"precision": _tiers([0.98, 0.97], 0.90, [0.96, 0.99]), "hard": _tiers([0.90, 0.90], 0.90, [0.88, 0.92])}
    eps = {"precision": {"lqr": lqr, "precision_ppo_seed0": better, "precision_ppo_seed1": same},
           "hard": {"lqr": lqr, "hard_ppo_seed0": same, "hard_ppo_seed1": same}}
    t = target(tiers, eps)
    assert t["tiers"]["precision"]["significantly_better"] and t["tiers"]["precision"]["best_run"] == "precision_ppo_seed0"
    assert t["tiers"]["precision"]["p_value"] == pytest.approx(2 * 0.5 ** 8)
    assert t["tiers"]["hard"]["at_least_classical"] and not t["tiers"]["hard"]["significantly_better"]
    assert t["met"]
    # a learned method whose seeds spread by more than 20 points fails the target, even beside a
    # better method of the same tier; the verdict names it
    tiers["hard"] = _tiers([0.95, 0.70], 0.90, [0.70, 0.95])
    tiers["hard"]["policies"]["residual_sac"] = {"kind": "learned", "rates": [0.96, 0.95], "iqm": 0.955,
                                                 "ci95": [0.93, 0.97]}
    eps["hard"].update(hard_residual_sac_seed0=better, hard_residual_sac_seed1=better)
    t = target(tiers, eps)
    assert not t["tiers"]["hard"]["spread_ok"] and not t["met"]
    assert t["tiers"]["hard"]["method"] == "residual_sac" and t["tiers"]["hard"]["widest_spread_method"] == "ppo"
    assert t["tiers"]["hard"]["max_seed_spread"] == pytest.approx(0.25)
    # below the LQR with an interval that does not reach it fails too
    tiers["hard"] = _tiers([0.80, 0.80], 0.90, [0.76, 0.84])
    assert not target(tiers, eps)["tiers"]["hard"]["at_least_classical"]


def test_the_target_scores_the_precision_and_hard_tiers_and_the_spread_on_every_tier():
    lqr = [True] * 90 + [False] * 10
    better = [True] * 98 + [False] * 2
    tiers = {"nominal": _tiers([0.99, 0.99], 1.0, [0.98, 1.0]),
             "precision": _tiers([0.98, 0.98], 0.90, [0.96, 0.99]), "hard": _tiers([0.90, 0.90], 0.90, [0.88, 0.92])}
    eps = {"nominal": {"lqr": [True] * 100, "nominal_ppo_seed0": [True] * 99 + [False]},
           "precision": {"lqr": lqr, "precision_ppo_seed0": better}, "hard": {"lqr": lqr, "hard_ppo_seed0": lqr}}
    t = target(tiers, eps)
    # one episode short of a perfect LQR on the nominal tier: shown, not scored
    assert not t["tiers"]["nominal"]["at_least_classical"] and not t["tiers"]["nominal"]["scored"]
    assert t["tiers"]["precision"]["scored"] and t["tiers"]["hard"]["scored"] and t["met"]
    md = _target_report(t)
    assert "On the precision and hard tiers" in md and "| nominal | PPO 99.0 %" in md and "| - | - |" in md
    # the spread criterion holds on every tier
    tiers["nominal"] = _tiers([0.99, 0.60], 1.0, [0.6, 1.0])
    t = target(tiers, eps)
    assert not t["met"] and "- nominal: PPO's seeds spread by 39.0 points" in _target_report(t)
    # a config without the target tiers scores every tier it has
    t = target({"nominal": tiers["nominal"]}, {"nominal": eps["nominal"]})
    assert t["tiers"]["nominal"]["scored"]


def _target_report(t):
    doc = {"config": {"learners": {}, "episodes": 1, "source": "x"}, "command": "c", "date": "d", "machine": "m",
           "wall_time_s": 60, "jobs_wall_s": 0, "baseline_wall_s": 60, "tiers": {}, "runs": [], "target": t}
    return report_markdown(doc)


def test_report_has_a_target_section_only_with_its_numbers():
    doc = {"config": {"learners": {}, "episodes": 1, "source": "x"}, "command": "c", "date": "d", "machine": "m",
           "wall_time_s": 60, "jobs_wall_s": 0, "baseline_wall_s": 60, "tiers": {}, "runs": []}
    assert "## Target" not in report_markdown(doc)
    lqr = [True, False]
    doc["target"] = target({"hard": _tiers([1.0], 0.5, [1.0, 1.0])}, {"hard": {"lqr": lqr, "hard_ppo_seed0": [True, True]}})
    md = report_markdown(doc)
    assert "## Target" in md and "Target not met on these runs:" in md and "| hard | PPO 100.0 %" in md
    assert "| 0.0 points, PPO (yes) |" in md
    # why it is not met, with the numbers: 2 episodes cannot make p < 0.05
    assert "- no tier's chosen run captures significantly more than the best classical controller (smallest p: hard, 1)." in md
    doc["target"] = target({"hard": _tiers([1.0, 0.5], 0.5, [0.5, 1.0])},
                           {"hard": {"lqr": lqr, "hard_ppo_seed0": [True, True], "hard_ppo_seed1": [True, False]}})
    assert "- hard: PPO's seeds spread by 50.0 points, 30.0 more than the 20 allowed." in report_markdown(doc)


def test_method_labels():
    from accd_gym.evals.benchmark import method_label

    assert [method_label(a) for a in ("ppo", "residual_sac", "residual_ppo", "tqc")] == [
        "PPO", "residual SAC", "residual PPO", "TQC"]


def test_failure_table_numbers_by_hand():
    from accd_gym.evals.benchmark import failures

    rec = {"captured": [True, False, False, True], "outcome": ["captured", "truncated", "crashed", "captured"],
           "min_distance": [0.1, 0.8, 0.4, 0.2], "closest_speed": [1.0, 3.0, 5.0, 2.0],
           "final_speed": [1.5, 0.5, 0.7, 2.5], "capture_time": [10.0, None, None, 20.0]}
    f = failures([rec, {k: v[:1] for k, v in rec.items()}])
    assert f["episodes"] == 5 and f["missed"] == 2 and f["outcomes"] == {"truncated": 1, "crashed": 1}
    assert f["missed_miss_median_m"] == pytest.approx(0.6) and f["missed_closest_speed_median_mps"] == 4.0
    assert f["capture_speed_median_mps"] == 1.5 and f["capture_time_median_s"] == 10.0
    # records written before the speeds were recorded give None, not an error
    old = {k: v for k, v in rec.items() if "speed" not in k}
    assert failures([old])["capture_speed_median_mps"] is None


def test_episodes_record_the_closing_speeds_from_their_trajectory():
    import numpy as np

    from accd_gym.control.registry import make_controller
    from accd_gym.evals.episodes import run_episodes

    for e in run_episodes(make_controller("lqr", 0, None), 2, num_envs=2):
        p = e.trajectory.astype(np.float64)
        dt = e.time / e.steps
        assert e.final_speed == pytest.approx(np.linalg.norm(p[-1] - p[-2]) / dt)
        k = int(np.argmin(np.linalg.norm(p, axis=1)))
        assert e.closest_speed == pytest.approx(np.linalg.norm(p[k] - p[k - 1]) / dt)
        assert 0 < e.closest_speed < 50


def test_the_choice_is_made_on_validation_episodes_and_never_reads_held_out_results():
    """Held-out records that would choose another run and method are given beside validation
    records: the choice follows the validation records alone."""
    lqr = [True] * 90 + [False] * 10
    held_out = {"hard": {"lqr": lqr,
                         "hard_ppo_seed0": [True] * 100,                 # best on held-out
                         "hard_ppo_seed1": [True] * 90 + [False] * 10,
                         "hard_sac_seed0": [True] * 99 + [False]}}
    validation = {"hard": {"ppo": {"hard_ppo_seed0": [True] * 80 + [False] * 20,
                                   "hard_ppo_seed1": [True] * 95 + [False] * 5},   # best on validation
                           "sac": {"hard_sac_seed0": [True] * 70 + [False] * 30}}}
    tiers = {"hard": {"policies": {"ppo": {"kind": "learned", "rates": [1.0, 0.9], "iqm": 0.95, "ci95": [0.9, 1.0]},
                                   "sac": {"kind": "learned", "rates": [0.99], "iqm": 0.99, "ci95": [0.97, 1.0]},
                                   "lqr": {"kind": "classical", "rate": 0.9}}}}
    v = _target(tiers, held_out, validation)["tiers"]["hard"]
    assert v["method"] == "ppo" and v["best_run"] == "hard_ppo_seed1"
    # the comparison is reported on the held-out episodes of the chosen run
    assert (v["only_learned"], v["only_classical"]) == (0, 0)
    assert choose_run(validation["hard"]["ppo"]) == "hard_ppo_seed1"
    assert choose_method(validation["hard"]) == "ppo"
    # a held-out record in the place of a validation one would choose otherwise: the choice reads
    # what it is given and nothing else
    assert choose_run({k: held_out["hard"][k] for k in ("hard_ppo_seed0", "hard_ppo_seed1")}) == "hard_ppo_seed0"


def test_summarize_chooses_the_mcnemar_pair_on_validation_episodes():
    from accd_gym.evals.benchmark import summarize

    def result(seed, held_out, validation):
        return {"job": {"tier": "hard", "algo": "ppo", "seed": seed}, "name": f"hard_ppo_seed{seed}",
                "train_wall_s": 1.0, "steps_per_s": 1.0,
                "episodes": {"captured": held_out, "min_distance": [0.1] * 4, "capture_time": [1.0] * 4},
                "validation": {"captured": validation}}

    def baseline(held_out, validation):
        return {"captured": held_out, "min_distance": [0.1] * 4, "capture_time": [1.0] * 4,
                "outcome": ["captured"] * 4, "validation": {"captured": validation}}

    results = [result(0, [True] * 4, [True, False, False, False]), result(1, [True, True, False, False], [True] * 4)]
    baselines = {"hard": {"lqr": baseline([True, True, True, False], [True, False, False, False]),
                          "guidance": baseline([False] * 4, [True, True, False, False])}}
    cfg = {"tiers": ["hard"], "learners": {"ppo": {}}}
    t = summarize(cfg, results, baselines)["hard"]
    m = t["mcnemar"]
    assert (m["learned"], m["classical"]) == ("hard_ppo_seed1", "guidance")
    assert t["policies"]["ppo"]["chosen_run"] == "hard_ppo_seed1"
    assert (m["learned_rate"], m["classical_rate"]) == (0.5, 0.0)  # reported on the held-out episodes


def _family_tiers(standalone_rates, hybrid_rates, lqr_rate):
    def row(rates, family):
        return {"kind": "learned", "family": family, "rates": rates, "iqm": sorted(rates)[len(rates) // 2],
                "ci95": [min(rates), max(rates)]}
    return {"policies": {"dagger": row(standalone_rates, "standalone"), "residual_sac": row(hybrid_rates, "hybrid"),
                         "lqr": {"kind": "classical", "rate": lqr_rate}, "mpc": {"kind": "classical", "rate": 0.5}},
            "best": {"classical": "lqr", "hybrid": "residual_sac", "standalone": "dagger"}}


def test_the_standalone_target_needs_significance_the_hybrid_level_and_a_10_point_spread():
    lqr = [True] * 90 + [False] * 10
    better = [True] * 98 + [False] * 2                       # 8 gained over the LQR: p = 2 * 0.5**8
    eps = {"hard": {"lqr": lqr, "mpc": [True] * 50 + [False] * 50, "hard_dagger_seed0": better,
                    "hard_dagger_seed1": better, "hard_dagger_seed2": better,
                    "hard_residual_sac_seed0": lqr, "hard_residual_sac_seed1": lqr}}
    tiers = {"hard": _family_tiers([0.98, 0.97, 0.98], [0.96, 0.95], 0.90)}
    t = target(tiers, eps, family="standalone")
    v = t["tiers"]["hard"]
    assert t["met"] and v["method"] == "dagger" and v["classical"] == "lqr" and v["hybrid_method"] == "residual_sac"
    assert v["significantly_better"] and v["above_classical"] and v["at_least_hybrid"] and v["spread_ok"]
    assert t["max_spread"] == pytest.approx(0.10)
    # below the hybrid's IQM fails, and says by how much
    tiers = {"hard": _family_tiers([0.94, 0.94, 0.94], [0.96, 0.95], 0.90)}
    t = target(tiers, eps, family="standalone")
    assert not t["met"] and not t["tiers"]["hard"]["at_least_hybrid"]
    assert "- hard: DAgger's IQM 94.0 % is below the best hybrid method, residual SAC, at 96.0 %." in _target_report_lines(t)
    # 11 points between seeds fails the standalone spread (10), though it passes the benchmark's (20)
    tiers = {"hard": _family_tiers([0.98, 0.97, 0.87], [0.96, 0.95], 0.90)}
    assert not target(tiers, eps, family="standalone")["tiers"]["hard"]["spread_ok"]
    assert target(tiers, eps)["tiers"]["hard"]["spread_ok"]
    # the hybrid family alone never counts for the standalone target
    only_hybrid = {"hard": {"policies": {k: v for k, v in _family_tiers([0.9], [0.96, 0.95], 0.9)["policies"].items()
                                         if k != "dagger"}}}
    assert target(only_hybrid, eps, family="standalone") is None


def _target_report_lines(t):
    return _target_report(t).splitlines()


def test_the_reference_is_the_best_classical_controller_chosen_on_validation():
    """With an MPC beside the LQR, the verdict is read against the controller the validation
    episodes chose, on the held-out episodes."""
    lqr = [True] * 90 + [False] * 10
    mpc = [True] * 95 + [False] * 5
    better = [True] * 98 + [False] * 2
    tiers = {"hard": {"policies": {"ppo": {"kind": "learned", "family": "standalone", "rates": [0.98], "iqm": 0.98,
                                           "ci95": [0.96, 0.99]},
                                   "lqr": {"kind": "classical", "rate": 0.90}, "mpc": {"kind": "classical", "rate": 0.95}},
                      "best": {"classical": "mpc"}}}
    v = target(tiers, {"hard": {"lqr": lqr, "mpc": mpc, "hard_ppo_seed0": better}})["tiers"]["hard"]
    assert (v["classical"], v["classical_rate"], v["only_learned"], v["only_classical"]) == ("mpc", 0.95, 3, 0)
    assert not v["significantly_better"]  # 3 / 0: p = 0.25


def _recipe(tmp_path, name, env):
    import json

    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps({"algo": "ppo", "env": env}))
    return str(path)


def test_summarize_names_families_the_best_of_each_and_normalizes_by_the_best_classical(tmp_path):
    from accd_gym.evals.benchmark import learner_family, summarize

    def result(algo, seed, held_out, validation):
        return {"job": {"tier": "hard", "algo": algo, "seed": seed}, "name": f"hard_{algo}_seed{seed}",
                "train_wall_s": 1.0, "steps_per_s": 1.0,
                "episodes": {"captured": held_out, "min_distance": [0.1] * 4, "capture_time": [1.0] * 4},
                "validation": {"captured": validation}}

    def baseline(held_out, validation):
        return {"captured": held_out, "min_distance": [0.1] * 4, "capture_time": [1.0] * 4,
                "outcome": ["captured"] * 4, "validation": {"captured": validation}}

    hybrid = {"train_config": {"hard": _recipe(tmp_path, "r", {"residual": {"base": "lqr", "scale": 0.3}})}}
    plain = {"train_config": _recipe(tmp_path, "p", {"history": 4})}
    assert (learner_family(hybrid), learner_family(plain), learner_family({})) == ("hybrid", "standalone", "standalone")
    cfg = {"tiers": ["hard"], "learners": {"residual_sac": hybrid, "ppo": plain, "dagger": plain}}
    results = [result("residual_sac", 0, [True] * 4, [True] * 4),
               result("ppo", 0, [True] * 4, [True, False, False, False]),        # best held-out, worse validation
               result("dagger", 0, [True, True, False, False], [True, True, True, False])]
    baselines = {"hard": {"lqr": baseline([True, True, True, False], [True, True, False, False]),
                          "mpc": baseline([True, True, False, False], [True, True, True, False]),
                          "zero": baseline([False] * 4, [True] * 4)}}           # trivial: never the classical choice
    t = summarize(cfg, results, baselines)["hard"]
    assert t["best"] == {"classical": "mpc", "hybrid": "residual_sac", "standalone": "dagger"}
    assert t["policies"]["residual_sac"]["family"] == "hybrid" and t["policies"]["dagger"]["family"] == "standalone"
    assert t["policies"]["zero"]["kind"] == "trivial"
    # relative to the MPC's held-out rate 0.5
    assert t["policies"]["dagger"]["vs_classical"][0] == pytest.approx(0.5 / 0.5)
    assert t["policies"]["ppo"]["vs_classical"][0] == pytest.approx(1.0 / 0.5)
    assert t["mcnemar"]["classical"] == "mpc"


def test_the_readme_table_is_written_between_its_markers_and_only_there(tmp_path):
    from accd_gym.errors import ConfigError
    from accd_gym.evals.benchmark import README_BEGIN, README_END, readme_table, write_readme_table

    row = lambda iqm, fam: {"kind": "learned", "family": fam, "rates": [iqm] * 5, "iqm": iqm, "ci95": [iqm, iqm]}  # noqa: E731
    doc = {"tiers": {"hard": {"policies": {"lqr": {"kind": "classical", "rate": 0.938},
                                           "mpc": {"kind": "classical", "rate": 0.95},
                                           "zero": {"kind": "trivial", "rate": 0.0},
                                           "residual_sac": row(0.959, "hybrid"), "dagger": row(0.94, "standalone")},
                              "best": {"classical": "mpc", "hybrid": "residual_sac", "standalone": "dagger"}},
                     "nominal": {"policies": {"lqr": {"kind": "classical", "rate": 1.0},
                                              "mpc": {"kind": "classical", "rate": 1.0},
                                              "zero": {"kind": "trivial", "rate": 0.134}},
                                 "best": {"classical": "mpc", "hybrid": None, "standalone": None}}}}
    table = readme_table(doc)
    assert "best hybrid, IQM of 5 seeds" in table and "(`lqr`)" in table and "(`mpc`)" in table
    assert "| hard | 93.8 % | 95.0 % | 95.9 % (residual SAC) | 94.0 % (DAgger) | 0.0 % |" in table
    assert "| nominal | 100.0 % | 100.0 % | - | - | 13.4 % |" in table and "neutral flaps throughout (`zero`)" in table
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\n{README_BEGIN}\nold table\n{README_END}\n\nafter\n")
    write_readme_table(readme, doc)
    text = readme.read_text()
    assert "old table" not in text and table in text and text.startswith("# x\n") and text.endswith("after\n")
    readme.write_text("no markers\n")
    with pytest.raises(ConfigError, match="has no block between"):
        write_readme_table(readme, doc)
    assert readme.read_text() == "no markers\n"
