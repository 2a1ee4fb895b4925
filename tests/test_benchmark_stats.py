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


def target(tiers, eps, validation=None):
    return _target(tiers, eps, _validation_as_held_out(eps) if validation is None else validation)


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
    assert t["tiers"]["hard"]["at_least_lqr"] and not t["tiers"]["hard"]["significantly_better"]
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
    assert not target(tiers, eps)["tiers"]["hard"]["at_least_lqr"]


def test_the_target_scores_the_precision_and_hard_tiers_and_the_spread_on_every_tier():
    lqr = [True] * 90 + [False] * 10
    better = [True] * 98 + [False] * 2
    tiers = {"nominal": _tiers([0.99, 0.99], 1.0, [0.98, 1.0]),
             "precision": _tiers([0.98, 0.98], 0.90, [0.96, 0.99]), "hard": _tiers([0.90, 0.90], 0.90, [0.88, 0.92])}
    eps = {"nominal": {"lqr": [True] * 100, "nominal_ppo_seed0": [True] * 99 + [False]},
           "precision": {"lqr": lqr, "precision_ppo_seed0": better}, "hard": {"lqr": lqr, "hard_ppo_seed0": lqr}}
    t = target(tiers, eps)
    # one episode short of a perfect LQR on the nominal tier: shown, not scored
    assert not t["tiers"]["nominal"]["at_least_lqr"] and not t["tiers"]["nominal"]["scored"]
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
    assert "- no tier's chosen run captures significantly more than the LQR (smallest p: hard, 1)." in md
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
    assert (v["only_learned"], v["only_lqr"]) == (0, 0)
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
