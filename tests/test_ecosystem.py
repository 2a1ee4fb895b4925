"""The tools users bring: rl-zoo3 with the shipped hyperparameters, the CLI without
stable-baselines3, mypy --strict on a user's script, and input the envs must refuse.
"""

import json
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import gymnasium as gym

import accd_gym
from accd_gym import ENV_ID

ROOT = pathlib.Path(__file__).resolve().parent.parent
QUICK = dict(capture_window=2.0, initial={"settle_time": 20.0})


def run_python(code: str, *args: str, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    env = dict(os.environ, MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)


# -- rl-zoo3 ---------------------------------------------------------------------------------


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_zoo_hyperparameters_are_the_training_recipes_for_every_registered_id(algo):
    from accd_gym.zoo import RECIPES
    import importlib

    recipe = json.loads((ROOT / "training" / f"{algo}.json").read_text())
    for key, value in RECIPES[algo].items():
        assert recipe[key] == value, key
    hyperparams = importlib.import_module(f"accd_gym.zoo.{algo}").hyperparams
    ours = [env_id for env_id in gym.registry if env_id.startswith("accd_gym/")]
    from accd_gym.envs.tiers import TIERS

    assert sorted(hyperparams) == sorted(ours) == sorted(t.id for t in TIERS.values())
    assert all(hyperparams[i] == hyperparams[ENV_ID] for i in ours)  # one recipe for every tier
    entry = hyperparams[ENV_ID]
    assert entry["n_envs"] == recipe["num_envs"] and eval(entry["normalize"]) == recipe["vec_normalize"]


def test_rl_zoo3_trains_with_the_shipped_hyperparameters(tmp_path):
    pytest.importorskip("rl_zoo3")
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID, "--gym-packages", "accd_gym",
        "--conf-file", "accd_gym.zoo.ppo", "-n", "2000", "--log-folder", str(tmp_path), "--eval-freq", "-1",
        "--seed", "0",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, cwd=tmp_path,
                          env=dict(os.environ, MPLBACKEND="Agg"))
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Using 16 environments" in done.stdout and "Normalization activated" in done.stdout
    run = tmp_path / "ppo" / "accd_gym-InAirCapture-v0_1"
    assert (run / "accd_gym-InAirCapture-v0.zip").is_file()
    assert (run / "accd_gym-InAirCapture-v0" / "vecnormalize.pkl").is_file()


# -- without stable-baselines3 ----------------------------------------------------------------

WITHOUT_SB3 = """
import sys
for name in ("stable_baselines3", "torch"):
    sys.modules[name] = None  # as after a plain `pip install accd-gym`
"""


def test_rollout_of_a_baseline_works_without_stable_baselines3():
    code = WITHOUT_SB3 + textwrap.dedent("""
        from accd_gym.cli import main
        sys.exit(main(sys.argv[1:]))
    """)
    done = run_python(code, "rollout", "--policy", "guidance", "--episodes", "2", "--num-envs", "2", "--quiet",
                      "--env", json.dumps({"capture_window": 3.0}))
    assert done.returncode == 0, done.stderr
    assert "guidance: " in done.stdout and "captured" in done.stdout


def test_what_needs_stable_baselines3_names_the_extra():
    code = WITHOUT_SB3 + textwrap.dedent("""
        import accd_gym
        try:
            accd_gym.AccdVecEnv
        except ModuleNotFoundError as e:
            print(e)
        from accd_gym.cli import main
        sys.exit(main(sys.argv[1:]))
    """)
    done = run_python(code, "train", "--config", str(ROOT / "training" / "ppo.json"), "--timesteps", "10",
                      "--out", "/nonexistent/never-written", "--quiet")
    assert "pip install 'accd-gym[sb3]'" in done.stdout, done.stdout + done.stderr
    assert done.returncode == 2 and "needs the sb3 extra" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


# -- mypy --strict on a user's script ------------------------------------------------------------

EXAMPLE = '''
"""A user's script: the typed surface of accd_gym."""
import numpy as np

import accd_gym
from accd_gym import AccdVecEnv, InAirCaptureEnv, InAirCaptureVectorEnv


def run() -> float:
    env = InAirCaptureEnv(capture_window=2.0)
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(np.zeros(4, np.float32))
    vec = InAirCaptureVectorEnv(2, capture_window=2.0)
    vobs, vinfo = vec.reset(seed=[1, 2])
    sb3 = AccdVecEnv(2, capture_window=2.0)
    first = sb3.reset()
    low, high = accd_gym.reward_bounds()
    seeds: range = accd_gym.HELD_OUT_WAKE_SEEDS
    return float(reward) + float(first.sum()) + low + high + len(seeds) + float(vobs.sum())
'''

TYPOS = '''
import accd_gym

x: int = accd_gym.HELD_OUT_WAKE_SEED
y: int = accd_gym.AccdVecEnv
'''


def test_mypy_strict_passes_on_a_users_script_and_catches_typos(tmp_path):
    pytest.importorskip("mypy")
    # torch's own sources take mypy half a minute; its types are not what is checked here.
    (tmp_path / "mypy.ini").write_text("[mypy]\nstrict = True\n\n[mypy-torch.*]\nfollow_imports = skip\n")
    (tmp_path / "example.py").write_text(EXAMPLE)
    (tmp_path / "typos.py").write_text(TYPOS)
    mypy = [sys.executable, "-m", "mypy", "--config-file", "mypy.ini", "--cache-dir", str(tmp_path / "cache")]
    good = subprocess.run([*mypy, "example.py"], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert good.returncode == 0, good.stdout + good.stderr
    bad = subprocess.run([*mypy, "typos.py"], capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert 'Module has no attribute "HELD_OUT_WAKE_SEED"' in bad.stdout, bad.stdout
    assert 'type "type[AccdVecEnv]"' in bad.stdout, bad.stdout  # AccdVecEnv is a class, not Any


# -- input the envs refuse (env strictness) ---------------------------------------------


@pytest.mark.parametrize("bad", [1.9, "7", True, -1, 2**63, [3, "x"]])
def test_bad_wake_seeds_are_refused(bad):
    env = accd_gym.InAirCaptureEnv(**QUICK)
    key = "wake_seeds" if isinstance(bad, list) else "wake_seed"
    with pytest.raises(accd_gym.ConfigError, match=key):
        env.reset(seed=0, options={key: bad})


def test_numpy_integer_seeds_and_wake_seeds_are_accepted():
    env = accd_gym.InAirCaptureEnv(**QUICK)
    a = env.reset(seed=np.int64(12), options={"wake_seed": np.uint32(5)})
    b = env.reset(seed=12, options={"wake_seed": 5})
    assert np.array_equal(a[0], b[0]) and a[1] == b[1] == {"wake_seed": 5}
    vec = accd_gym.InAirCaptureVectorEnv(2, **QUICK)
    obs, _ = vec.reset(seed=np.int64(12))
    np.testing.assert_array_equal(obs[0], b[0])
    obs, _ = vec.reset(seed=np.array([12, 13]))
    np.testing.assert_array_equal(obs[0], b[0])


@pytest.mark.parametrize("bad", ["12", 1.0, True, -3, None.__class__])
def test_bad_reset_seeds_are_refused(bad):
    for env in (accd_gym.InAirCaptureEnv(**QUICK), accd_gym.InAirCaptureVectorEnv(2, **QUICK)):
        with pytest.raises(accd_gym.ConfigError, match="seed"):
            env.reset(seed=bad)
    with pytest.raises(accd_gym.ConfigError, match="seed"):
        accd_gym.InAirCaptureVectorEnv(2, **QUICK).reset(seed=[1, bad])


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.full(4, 1 + 2j), "real numbers"),
        (np.array(["a", "b", "c", "d"]), "real numbers"),
        (np.ones(4, dtype=bool), "real numbers"),
        ([True, False, True, False], "real numbers"),
        (np.zeros((1, 4), np.float32), r"shape \(1, 4\), expected \(4,\)"),
        (np.zeros(5, np.float32), "shape"),
        (np.array([0.0, 1e39, 0.0, 0.0]), "outside float32's range"),
    ],
)
def test_bad_actions_are_refused_with_what_is_wrong(bad, message):
    env = accd_gym.InAirCaptureEnv(**QUICK)
    env.reset(seed=0)
    with pytest.raises(accd_gym.StateError, match=message) as e:
        env.step(bad)
    assert "non-finite" not in str(e.value)
    with pytest.raises(accd_gym.StateError, match="non-finite"):
        env.step(np.array([0.0, np.inf, 0.0, 0.0]))
    obs, *_ = env.step(np.array([0, 1, 0, 0]))  # integers are numbers
    assert obs.dtype == np.float32


def test_accd_vec_env_reset_infos_follow_automatic_resets():
    env = accd_gym.AccdVecEnv(2, seed=3, **QUICK)
    env.set_options({"wake_seeds": [1_000_000_000 + i for i in range(6)]})
    env.reset()
    assert [i["wake_seed"] for i in env.reset_infos] == [1_000_000_000, 1_000_000_001]
    for _ in range(20):
        _, _, dones, infos = env.step(np.zeros((2, 4), np.float32))
    assert dones.all()
    assert [i["wake_seed"] for i in env.reset_infos] == [1_000_000_002, 1_000_000_003]
    assert [i["wake_seed"] for i in infos] == [1_000_000_000, 1_000_000_001]


# -- CleanRL's env stack (ppo_continuous_action.py's make_env, and its vector-wrapper variant) ----


def cleanrl_single(gamma=0.99):
    env = gym.make(ENV_ID, **QUICK)
    env = gym.wrappers.FlattenObservation(env)
    env = gym.wrappers.RecordEpisodeStatistics(env)
    env = gym.wrappers.ClipAction(env)
    env = gym.wrappers.NormalizeObservation(env)
    env = gym.wrappers.TransformObservation(env, lambda obs: np.clip(obs, -10, 10), env.observation_space)
    env = gym.wrappers.NormalizeReward(env, gamma=gamma)
    return gym.wrappers.TransformReward(env, lambda reward: np.clip(reward, -10, 10))


def cleanrl_native(num_envs, gamma=0.99):
    from gymnasium.wrappers import vector as vw

    envs = gym.make_vec(ENV_ID, num_envs=num_envs, **QUICK)
    envs = vw.RecordEpisodeStatistics(vw.ClipAction(envs))
    envs = vw.NormalizeObservation(envs)
    envs = vw.TransformObservation(envs, lambda obs: np.clip(obs, -10, 10))
    envs = vw.NormalizeReward(envs, gamma=gamma)
    return vw.TransformReward(envs, lambda reward: np.clip(reward, -10, 10))


@pytest.mark.parametrize("kind", ["sync", "native"])
def test_cleanrl_style_rollouts_log_episode_statistics(kind):
    envs = gym.vector.SyncVectorEnv([cleanrl_single for _ in range(2)]) if kind == "sync" else cleanrl_native(2)
    assert isinstance(envs.single_action_space, gym.spaces.Box)
    next_obs, _ = envs.reset(seed=1)
    rng = np.random.default_rng(0)
    returns = []
    for _ in range(45):  # CleanRL: envs.step(action); "episode" in infos at episode ends
        action = rng.normal(size=envs.action_space.shape).astype(np.float32)
        next_obs, reward, terminations, truncations, infos = envs.step(action)
        assert np.all(np.abs(next_obs) <= 10) and np.all(np.abs(reward) <= 10)
        if "episode" in infos:
            returns += list(infos["episode"]["r"][infos["_episode"]])
    assert len(returns) >= 2
