"""The evaluation's episode definition, which distributed evaluation relies on (no Ray needed).

Episode k is the first episode of a single env seeded ``seed + k`` with wake seed
``wake_seeds[k]``; the results must not depend on ``num_envs`` nor on how the episode range is
split into parts of the same batch size (what each Ray task runs).
"""

import numpy as np
import pytest

import accd_gym
from accd_gym.control.baselines import GuidancePolicy, RandomPolicy
from accd_gym.evals.evaluation import run_episode_range, run_episodes
from accd_gym.evals.sweep import bootstrap_interval, iqm

SHORT = {"capture_window": 6.0}
WAKE = list(accd_gym.HELD_OUT_WAKE_SEEDS[:40])


def _same(a, b):
    """Bitwise equality of two episode lists (metrics and trajectories)."""
    assert [e.index for e in a] == [e.index for e in b]
    for e, f in zip(a, b):
        assert e.metrics() == f.metrics(), (e.index, e.metrics(), f.metrics())
        assert np.array_equal(e.trajectory, f.trajectory)


def _split(policy_factory, parts, batch, **kw):
    """Runs consecutive index ranges (as separate tasks would, each with its own policy copy)."""
    out = []
    for a, b in parts:
        out += run_episode_range(policy_factory(), a, b, batch=batch, **kw)
    return out


def test_start_episode_replays_the_single_env_with_that_seed_and_wake():
    vec = accd_gym.InAirCaptureVectorEnv(3, autoreset_mode="disabled", num_threads=1, **SHORT)
    vec.reset(seed=5)
    single = accd_gym.InAirCaptureVectorEnv(1, autoreset_mode="disabled", num_threads=1, **SHORT)
    obs1, info1 = single.reset(seed=77, options={"wake_seed": WAKE[3]})
    before = vec.step(np.zeros((3, 4), np.float32))[0].copy()
    obs = vec.start_episode(1, 77, WAKE[3])
    assert np.array_equal(obs[1], obs1[0]) and np.array_equal(obs[[0, 2]], before[[0, 2]])
    assert vec.np_random_seed[1] == 77 and vec.np_random_seed[0] == 5
    assert vec._core.wake_schedule()[0] == "training"  # the batch's schedule is kept
    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.uniform(-1, 1, (3, 4)).astype(np.float32)
        o3, r3, *_ = vec.step(a)
        o1, r1, *_ = single.step(a[1:2])
        assert np.array_equal(o3[1], o1[0]) and r3[1] == r1[0]
    with pytest.raises(accd_gym.ConfigError, match="env index `i` = 3"):
        vec.start_episode(3, 1)


@pytest.mark.parametrize("factory", [GuidancePolicy, lambda: RandomPolicy(4)], ids=["guidance", "random"])
def test_episodes_do_not_depend_on_num_envs_or_on_the_split(factory):
    kw = dict(wake_seeds=WAKE, num_threads=1, config=SHORT)
    ref = run_episodes(factory(), 11, num_envs=4, **kw)
    assert [e.wake_seed for e in ref] == WAKE[:11]
    _same(ref, _split(factory, [(0, 3), (3, 4), (4, 11)], 4, **kw))
    _same(ref, _split(factory, [(0, 6), (6, 11)], 4, **kw))
    _same(ref, run_episodes(factory(), 11, num_envs=7, **kw))  # numpy policies: any batch size


def test_training_wake_draws_follow_the_episode_seed():
    a = run_episodes(GuidancePolicy(), 5, seed=3, num_envs=2, num_threads=1, config=SHORT)
    b = _split(GuidancePolicy, [(0, 2), (2, 5)], 2, seed=3, num_threads=1, config=SHORT)
    _same(a, b)
    assert all(e.wake_seed < accd_gym.HELD_OUT_WAKE_SEEDS.start for e in a)


def test_a_pytorch_mlp_policy_gives_the_same_episodes_whatever_the_split():
    """PPO's MLP on CPU: same batch size, rows in other places and other neighbours, same bits."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from accd_gym.envs.sb3 import AccdVecEnv

    model = PPO("MlpPolicy", AccdVecEnv(4, **SHORT), seed=0, device="cpu", n_steps=8, batch_size=8)

    class Mlp:
        def predict(self, obs):
            return np.clip(model.predict(np.asarray(obs, np.float32), deterministic=True)[0], -1, 1)

    kw = dict(wake_seeds=WAKE, num_threads=1, config=SHORT)
    ref = run_episodes(Mlp(), 9, num_envs=4, **kw)
    _same(ref, _split(Mlp, [(0, 2), (2, 9)], 4, **kw))
    _same(ref, _split(Mlp, [(0, 5), (5, 7), (7, 9)], 4, **kw))


def test_episode_range_checks_its_arguments():
    with pytest.raises(accd_gym.ConfigError, match="episode range 3..3"):
        run_episode_range(GuidancePolicy(), 3, 3)
    with pytest.raises(accd_gym.ConfigError, match="`batch` = 0"):
        run_episode_range(GuidancePolicy(), 0, 2, batch=0)
    with pytest.raises(accd_gym.ConfigError, match="need at least 5"):
        run_episode_range(GuidancePolicy(), 0, 5, wake_seeds=WAKE[:4])


def test_iqm_and_bootstrap_interval_against_closed_forms():
    assert iqm([1, 2, 3, 4]) == 2.5  # int(0.25 * 4) = 1 cut from each end: mean(2, 3)
    assert iqm([0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 9.0]) == 1.0  # outliers cut
    assert iqm([0.3, 0.9]) == pytest.approx(0.6)  # n < 4: nothing cut
    assert iqm([5.0]) == 5.0
    x = np.random.default_rng(1).normal(size=40)
    scipy_stats = pytest.importorskip("scipy.stats")
    assert iqm(x) == pytest.approx(scipy_stats.trim_mean(x, 0.25), abs=1e-12)
    lo, hi = bootstrap_interval([0.5, 0.5, 0.5])
    assert lo == hi == 0.5  # no spread, no interval
    lo, hi = bootstrap_interval([0.0, 1.0], stat=np.mean, resamples=20_000)
    # Resampling two values: the mean is 0, 0.5 or 1 with probabilities 1/4, 1/2, 1/4.
    assert (lo, hi) == (0.0, 1.0)
    assert bootstrap_interval([0.1, 0.4, 0.8]) == bootstrap_interval([0.1, 0.4, 0.8])  # fixed generator


def test_without_ray_everything_else_works_and_ray_options_say_which_extra(tmp_path):
    """Ray stays optional: with ``ray`` unimportable the package, the new modules and a local
    evaluation work, and ``--ray`` / an RLlib config exit with status 2 naming the ray extra."""
    import subprocess
    import sys

    code = f"""
import sys, json
sys.modules['ray'] = None  # any `import ray` now raises ModuleNotFoundError
import accd_gym, accd_gym.evals.distributed, accd_gym.learning.rllib, accd_gym.evals.sweep
from accd_gym.cli import main
args = ['evaluate', '--policy', 'zero', '--episodes', '2', '--num-envs', '2', '--num-threads', '1',
        '--env', json.dumps({SHORT!r}), '--quiet', '--out', {str(tmp_path / 'e')!r}]
assert main(args) == 0
assert main(args + ['--ray']) == 2
assert main(args + ['--ray-chunk', '2']) == 2  # needs --ray
assert main(['train', '--config', 'training/rllib_ppo.json', '--out', {str(tmp_path / 'r')!r}, '--quiet']) == 2
assert main(['sweep', '--config', 'training/sweep_seeds.json', '--out', {str(tmp_path / 's')!r}]) == 2
print('ok')
"""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=300)
    assert done.returncode == 0 and done.stdout.strip().endswith("ok"), done.stderr[-3000:]
    assert "--ray-chunk sets the episodes per Ray task; it needs --ray" in done.stderr
    assert done.stderr.count("needs the ray extra") == 3 and "pip install 'accd-gym[ray]'" in done.stderr


def test_validation_episodes_are_training_episodes_and_never_the_held_out_ones(tmp_path):
    import json

    from accd_gym.evals import sweep
    from accd_gym.evals.episodes import EVAL_BASE_SEED, VALIDATION_BASE_SEED

    wake, base = sweep.eval_episodes("validation")
    assert wake == accd_gym.VALIDATION_WAKE_SEEDS and len(wake) == len(accd_gym.HELD_OUT_WAKE_SEEDS)
    assert wake.start in accd_gym.TRAINING_WAKE_SEEDS and wake[-1] in accd_gym.TRAINING_WAKE_SEEDS
    assert not set(wake) & set(accd_gym.HELD_OUT_WAKE_SEEDS)
    # Initial conditions other than the held-out evaluation's, for every episode index in use.
    assert abs(base - EVAL_BASE_SEED) >= len(wake)
    assert sweep.eval_episodes("held_out") == (accd_gym.HELD_OUT_WAKE_SEEDS, EVAL_BASE_SEED)
    train = tmp_path / "ppo.json"
    train.write_text(json.dumps({"algo": "ppo", "total_timesteps": 64, "num_envs": 4}))
    assert sweep.validate_config({"train_config": str(train)})["eval_split"] == "held_out"
    assert sweep.validate_config({"train_config": str(train), "eval_split": "validation"})["eval_split"] == "validation"
    with pytest.raises(accd_gym.ConfigError, match=r"`eval_split` = 'test' is outside the allowed range \['held_out', 'validation'\]"):
        sweep.validate_config({"train_config": str(train), "eval_split": "test"})
    with pytest.raises(accd_gym.ConfigError, match=r"`episodes` = 1001 is outside the allowed range 1..1000 \(validation"):
        sweep.validate_config({"train_config": str(train), "eval_split": "validation", "episodes": 1001})
    md = sweep.summary_markdown({"config": {"train_config": "x", "episodes": 8, "eval_split": "validation"},
                                 "trials": [], "failed": [], "aggregates": [], "wall_time_s": 1.0})
    assert "Validation: 8 episodes of training wake seeds" in md


def test_a_sweeps_baselines_run_on_its_episodes_without_the_agents_options(tmp_path):
    import json

    from accd_gym.control.registry import make_controller
    from accd_gym.evals import sweep

    train = tmp_path / "ppo.json"
    env = {**SHORT, "residual": {"base": "lqr", "scale": 0.3}}
    train.write_text(json.dumps({"algo": "ppo", "total_timesteps": 64, "num_envs": 4, "env": env}))
    cfg = sweep.validate_config({"train_config": str(train), "episodes": 4, "num_envs": 4, "eval_split": "validation",
                                 "baselines": ["lqr", "zero"]})
    rates = sweep.baseline_rates(cfg)
    wake, base = sweep.eval_episodes("validation")
    for name in ("lqr", "zero"):
        eps = run_episodes(make_controller(name, 0, SHORT), 4, seed=base, wake_seeds=list(wake[:4]), num_envs=2, config=SHORT)
        assert rates[name]["captures"] == sum(e.captured for e in eps) and rates[name]["episodes"] == 4
    with pytest.raises(accd_gym.ConfigError, match=r"`baselines` = \['pid'\] is outside the allowed values"):
        sweep.validate_config({"train_config": str(train), "baselines": ["pid"]})


def test_a_sweeps_trials_are_reported_finished_failed_or_unfinished():
    """A trial that stopped without an error (the sweep interrupted) is said to be unfinished
    and resumable, not 'failed: None'; an error is reported by its text."""
    from accd_gym.evals import sweep

    params = {"seed": 1, "point": {"algo_kwargs.learning_rate": 1e-4}}
    metrics = {"capture_rate": 0.5, "captures": 10, "episodes": 20, "seed": 1, "trainer": "sb3", "algo": "ppo",
               "timesteps": 64, "train_wall_s": 1.0, "steps_per_s": 64.0, "miss_distance_median_m": 0.2,
               "trial": sweep.trial_name(1, params["point"]), "status": "done", "run": "x"}
    finished, record = sweep.trial_record(params, metrics, None)
    assert finished and record["capture_rate"] == 0.5 and record["point"] == params["point"]
    assert record["capture_rate_ci95"][0] < 0.5 < record["capture_rate_ci95"][1]
    stopped, record = sweep.trial_record(params, {}, None)
    assert not stopped and record["error"] == sweep.UNFINISHED and record["trial"] == metrics["trial"]
    failed, record = sweep.trial_record(params, None, ValueError("bad\n  value"))
    assert not failed and record["error"] == "bad value"
    doc = {"config": {"train_config": "r.json", "eval_split": "validation", "episodes": 20}, "trials": [],
           "failed": [sweep.trial_record(params, {}, None)[1], record], "aggregates": [], "baselines": {},
           "wall_time_s": 1.0}
    table = sweep.summary_markdown(doc)
    assert f"| {sweep.UNFINISHED} |" in table and "| failed: bad value |" in table and "failed: None" not in table
