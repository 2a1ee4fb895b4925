"""Reliability: a regression test for each failure found: no panic
across the boundary, interruptible native loops, memory budgeting, stable steps for every valid
tether discretization, finite outputs after a divergence, strict inputs, readable errors."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import accd_gym
from accd_gym import ConfigError, SimulationError, StateError, _core

SHORT = {"capture_window": 5.0}

# The interruption tests send SIGINT to this process: it must raise KeyboardInterrupt even when
# the suite was started with SIGINT ignored (conftest.py).
pytestmark = pytest.mark.usefixtures("sigint_raises_keyboard_interrupt")


def _interrupt_after(seconds: float) -> threading.Timer:
    """Sends SIGINT to this process after ``seconds`` (Python raises KeyboardInterrupt in the
    main thread once a native loop checks its signals)."""
    timer = threading.Timer(seconds, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    return timer


# 1. No panic reaches Python ---------------------------------------------------------------


def test_read_only_observation_array_does_not_panic_the_vector_env():
    env = accd_gym.AccdVecEnv(num_envs=2, seed=3, num_threads=1, **SHORT)
    obs = env.reset()
    obs.flags.writeable = False
    kept = obs.copy()
    for _ in range(4):
        env.step_async(np.zeros((2, 4), np.float32))
        new, reward, dones, infos = env.step_wait()
        assert new.shape == (2, 25) and np.all(np.isfinite(new))
    assert np.array_equal(obs, kept)  # the caller's read-only array was left alone


def test_read_only_arrays_of_the_gymnasium_vector_env_are_left_alone():
    env = accd_gym.InAirCaptureVectorEnv(num_envs=2, **SHORT)
    obs, _ = env.reset(seed=1)
    obs.flags.writeable = False
    for _ in range(3):
        out = env.step(np.zeros((2, 4), np.float32))
        for a in out[:4]:
            if isinstance(a, np.ndarray):
                a.flags.writeable = False
    assert np.all(np.isfinite(out[0]))


def test_no_catch_unwind_turns_a_panic_into_a_divergence():
    """The batch crate reports a panic as an internal error and never as `diverged`."""
    text = open(os.path.join(os.path.dirname(__file__), "..", "crates", "batch", "src", "batch.rs")).read()
    job = text[text.index("let job = |("):text.index("let pool = &self.pool;")]
    assert "catch_unwind" not in job
    assert "BatchError::Internal" in text


# 2. Long native loops stay interruptible -------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        pytest.param(lambda: _towed().advance(1e9), id="Tether.advance(1e9)"),
        pytest.param(lambda: _towed().step(10**12), id="Tether.step(1e12)"),
        pytest.param(lambda: accd_gym.CaptureSim(calm=True).settle(1e9), id="CaptureSim.settle(1e9)"),
        pytest.param(lambda: accd_gym.CaptureSim().step(steps=10**12), id="CaptureSim.step(1e12)"),
        pytest.param(lambda: accd_gym.Tether({"time_step": 1e-7}).advance(1e3), id="time_step=1e-7"),
        pytest.param(lambda: accd_gym.InAirCaptureEnv(initial={"settle_time": 600.0}, tether={"segments": 300}),
                     id="env construction"),
    ],
)
def test_long_native_loops_raise_keyboard_interrupt_within_0_2_s(call):
    _assert_interrupted_within_0_2_s(call)


def _assert_interrupted_within_0_2_s(call, delay: float = 0.4) -> None:
    """Sends SIGINT ``delay`` s into ``call()`` and checks that the call itself (not a later
    sleep) raised KeyboardInterrupt less than 0.2 s after the signal."""
    returned = False
    _interrupt_after(delay)
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        call()
        returned = True
        time.sleep(5)  # not reached when the call was interrupted
    latency = time.monotonic() - t0 - delay
    assert not returned, "the call finished before the signal: it does not test the interruption"
    assert latency < 0.2, f"interrupted {latency:.3f} s after the signal"


# 10 s agent steps of 300 segments at a 1 ms physics step: one step of one env takes about 0.7 s on
# one thread of an idle machine (2 envs: about 1.4 s), well beyond the 0.25 s after which the
# signal comes.
LONG_STEP = dict(agent_step=10.0, capture_window=20.0, tether={"segments": 300, "time_step": 0.001},
                 initial={"settle_time": 1.0})


@pytest.mark.parametrize("make", ["AccdVecEnv", "InAirCaptureVectorEnv", "InAirCaptureEnv"])
def test_a_long_batch_step_raises_keyboard_interrupt_within_0_2_s_and_wants_a_reset(make):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the short settle starts outside the envelope; not the point here
        if make == "AccdVecEnv":
            env = accd_gym.AccdVecEnv(num_envs=2, seed=1, num_threads=1, **LONG_STEP)
            env.reset()

            def step():
                env.step_async(np.zeros((2, 4), np.float32))
                return env.step_wait()[0]
        elif make == "InAirCaptureVectorEnv":
            env = accd_gym.InAirCaptureVectorEnv(2, num_threads=1, **LONG_STEP)
            env.reset(seed=1)

            def step():
                return env.step(np.zeros((2, 4), np.float32))[0]
        else:
            env = accd_gym.InAirCaptureEnv(**LONG_STEP)
            env.reset(seed=1)

            def step():
                return env.step(np.zeros(4, np.float32))[0]

    _assert_interrupted_within_0_2_s(step, delay=0.25)  # well inside the step (LONG_STEP)
    # the envs stopped part-way through the step: the env says so until it is reset
    with pytest.raises(StateError, match=r"interrupted.*reset\(\)"):
        step()
    with pytest.raises(StateError, match="interrupted"):
        env.get_state()
    env.reset() if make == "AccdVecEnv" else env.reset(seed=1)
    env.get_state()
    assert np.all(np.isfinite(step()))


@pytest.mark.parametrize("make", ["AccdVecEnv", "InAirCaptureVectorEnv"])
def test_a_step_shared_with_the_calling_thread_raises_keyboard_interrupt_within_0_2_s(make):
    """Usual env steps (3 s agent steps, about 3 ms an env) run partly on the calling thread,
    which asks the signal handlers between its envs: 256 of them take about 0.3 s a step here."""
    kw = dict(agent_step=3.0, capture_window=60.0, boom={"capture_radius": 1e-6})
    if make == "AccdVecEnv":
        env = accd_gym.AccdVecEnv(num_envs=256, seed=1, **kw)
        env.reset()

        def step():
            env.step_async(np.zeros((256, 4), np.float32))
            return env.step_wait()[0]
    else:
        env = accd_gym.InAirCaptureVectorEnv(256, **kw)
        env.reset(seed=1)

        def step():
            return env.step(np.zeros((256, 4), np.float32))[0]

    step()  # the first step of a batch runs on the pool alone; later ones are shared
    t0 = time.perf_counter()
    step()
    if time.perf_counter() - t0 < 0.15:
        pytest.skip("this machine steps the batch too fast to interrupt it part-way")
    _assert_interrupted_within_0_2_s(step, delay=0.05)
    with pytest.raises(StateError, match=r"interrupted.*reset\(\)"):
        step()


def _towed() -> accd_gym.Tether:
    t = accd_gym.Tether()
    t.tow()
    return t


def test_an_interrupted_tether_keeps_a_consistent_state():
    t = _towed()
    _interrupt_after(0.3)
    with pytest.raises(KeyboardInterrupt):
        t.advance(1e9)
    steps = t.time / t.time_step
    assert t.time > 0 and abs(steps - round(steps)) < 1e-6  # whole steps only
    assert np.all(np.isfinite(t.q)) and np.all(np.isfinite(t.tensions()))
    before = t.time
    t.step(3)
    assert t.time == pytest.approx(before + 3 * t.time_step)


def test_interrupted_capture_sim_continues():
    s = accd_gym.CaptureSim(calm=True)
    _interrupt_after(0.3)
    with pytest.raises(KeyboardInterrupt):
        s.step(steps=10**12)
    t = s.time
    assert s.step(steps=2)["time"] == pytest.approx(t + 2 * s.time_step)


def test_airspeed_1e_6_no_longer_fills_an_empty_gust_history_for_hours():
    t0 = time.monotonic()
    env = accd_gym.InAirCaptureEnv(aircraft={"airspeed": 1e-6}, turbulence={"wake_turbulence": False},
                                   initial={"settle_time": 1.0})
    env.reset(seed=0)
    assert time.monotonic() - t0 < 10.0


# 3. Memory budget --------------------------------------------------------------------------


def test_a_batch_beyond_the_memory_budget_is_a_config_error_naming_the_estimate():
    big = {"aircraft": {"airspeed": 10.0}, "turbulence": {"history_distance_m": 5000.0}}
    with pytest.raises(ConfigError, match=r"num_envs.*MiB per env") as info:
        accd_gym.AccdVecEnv(num_envs=65_536, seed=0, **big)
    assert "budget" in str(info.value)


def test_one_env_beyond_the_budget_names_the_history_distance():
    with pytest.raises(ConfigError, match=r"turbulence.history_distance_m.*MiB"):
        accd_gym.InAirCaptureEnv(aircraft={"airspeed": 1e-6})


# 4. A configuration that validates can be built and stepped -------------------------------


@pytest.mark.parametrize(
    "tether",
    # 10 and 50 kg/m (24 mm) diverged 16-18 s into the settle until the substep estimate took the
    # effective axial mass 1 / (M^-1)_00
    [{"segments": 100}, {"segments": 300}, {"tangential_drag_coefficient": 1.0}, {"length": 10.0},
     {"time_step": 0.05}, {"mass_per_length": 10.0},
     {"mass_per_length": 50.0, "breaking_tension": 5e6}],
    ids=lambda d: ",".join(f"{k}={v}" for k, v in d.items()),
)
def test_configs_that_validate_build_and_step(tether):
    import warnings

    agent_step = max(0.1, tether.get("time_step", 0.01))
    # The boom is placed relative to each config's equilibrium: no limit needs relaxing
    # (a fixed boom was 62 m from tangential_drag_coefficient = 1's equilibrium, 89-183 m from the
    # heavy tethers': see test_an_equilibrium_outside_the_episode_limits_is_a_warning_naming_the_limit)
    limits = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # none of these starts outside the episode limits
        env = accd_gym.InAirCaptureEnv(tether=tether, agent_step=agent_step, capture_window=20 * agent_step,
                                       initial={"settle_time": 20.0}, limits=limits)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        for k in range(10):
            obs, reward, terminated, truncated, info = env.step(np.zeros(4, np.float32))
            assert not info["diverged"], info
            assert np.all(np.isfinite(obs))
            if terminated or truncated:
                break
        assert k > 0, f"seed {seed}: the episode ended at its first step: {info}"


HEAVY_LIMITS = {"max_distance": 1000.0}


@pytest.mark.parametrize("mass_per_length", [10.0, 50.0])
def test_heavy_tethers_step_a_whole_default_episode(mass_per_length):
    # The default env (40 s settle, 70 s capture window) with a 24 mm tether of 10 or 50 kg/m:
    # the physics substeps where the axial damping mode needs it, the agent step stays 0.1 s.
    # (The distance limit is relaxed: the heavy chain hangs the ACCD 89-183 m from the boom and
    # swings past 250 m; 50 kg/m peaks near 8e5 N, beyond 24 mm's 550 kN breaking tension, so it
    # is given a stronger tether: the test is that the physics steps, not that it holds.)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tether = {"mass_per_length": mass_per_length, "breaking_tension": 5e6}
        env = accd_gym.InAirCaptureEnv(tether=tether, limits=HEAVY_LIMITS)
    env.reset(seed=0)
    steps = 0
    for steps in range(1, 1000):
        obs, reward, terminated, truncated, info = env.step(np.zeros(4, np.float32))
        assert not info["diverged"], (steps, info)
        assert np.all(np.isfinite(obs))
        if terminated or truncated:
            break
    assert steps == 700 and truncated and not terminated, (steps, info)  # 70 s at 0.1 s


def test_an_equilibrium_outside_the_episode_limits_is_a_warning_naming_the_limit():
    # A boom at a fixed place (the first versions' placement) and a tether that hangs elsewhere.
    with pytest.warns(UserWarning, match=r"(\d+\.\d+) m .*limits\.max_distance = 60 m.*first step") as record:
        env = accd_gym.InAirCaptureEnv(tether={"tangential_drag_coefficient": 1.0}, capture_window=5.0,
                                       boom={"placement": "absolute"})
    import re

    distance = float(re.search(r"capture point (\d+\.\d+) m", str(record[0].message)).group(1))
    assert 60.0 < distance < 70.0
    ends = 0
    for seed in range(5):
        env.reset(seed=seed)
        ends += env.step(np.zeros(4, np.float32))[4]["envelope_exit"]
    assert ends >= 4  # what the warning says


@pytest.mark.parametrize("n", [100, 300])
def test_design_study_discretizations_run_at_the_default_step(n):
    t = accd_gym.Tether({"segments": n, "tip_mass": 50.0})
    t.tow()
    t.advance(10.0)
    assert np.all(np.isfinite(t.tensions())) and np.isfinite(t.energy()["total"])
    s = accd_gym.CaptureSim({"tether": {"segments": n}}, calm=True)
    s.settle(10.0)
    assert 1e3 < s.state()["attachment_tension"] < 1e5


def test_an_unstable_step_is_refused_with_the_largest_stable_step():
    with pytest.raises(ConfigError, match=r"time_step.*largest stable step") as info:
        accd_gym.Tether({"segments": 1000, "time_step": 1.0})
    assert "substeps" in str(info.value)


def test_flap_limit_beyond_the_aero_table_is_refused():
    with pytest.raises(ConfigError, match=r"accd.flap_limit_deg.*15"):
        accd_gym.InAirCaptureEnv(accd={"flap_limit_deg": 20.0})
    accd_gym.env_config(accd={"flap_limit_deg": 15.0})


# 5. Finite outputs after a SimulationError; strict inputs ---------------------------------


def test_outputs_after_a_divergence_are_the_last_finite_state():
    t = accd_gym.Tether({"segments": 300})
    t.tow()
    # an impossible start: every joint folded back and forth at 50 rad/s
    phi = np.where(np.arange(300) % 2 == 0, 0.3, -0.3)
    t.set_angles(phi, np.zeros(300), phi_rate=50 * np.sign(phi), psi_rate=np.zeros(300))
    with pytest.raises(SimulationError):
        t.advance(100.0)
    assert np.all(np.abs(t.q) <= 1e6) and np.all(np.abs(t.qd) <= 1e6)
    assert np.all(np.isfinite(t.tensions()))
    assert all(np.isfinite(v) for v in t.energy().values())


def test_mix_flaps_refuses_nan():
    with pytest.raises(StateError, match="pitch"):
        accd_gym.mix_flaps(float("nan"), 0.0, 0.0)
    assert accd_gym.mix_flaps(1.0, 0.0, 0.0) == [1.0, 1.0, 0.0, 0.0] or len(accd_gym.mix_flaps(1.0, 0.0, 0.0)) == 4


@pytest.mark.parametrize("seed", [1.9, "7", True, -1, 2**64])
def test_capture_sim_seeds_are_integers(seed):
    with pytest.raises(ConfigError, match="seed"):
        accd_gym.CaptureSim(seed=seed)
    with pytest.raises(ConfigError, match="wake_seed"):
        accd_gym.CaptureSim(wake_seed=seed)


def test_capture_sim_accepts_numpy_integer_seeds():
    s = accd_gym.CaptureSim(seed=np.int64(5), wake_seed=np.uint32(9))
    assert s.seeds == {"initial": 5, "wake": 9, "rlv": 5}


@pytest.mark.parametrize("bad", [[1j, 0, 0, 0], ["1", 0, 0, 0], [True, 0, 0, 0], [np.nan, 0, 0, 0], [0, 0, 0]])
def test_capture_sim_flap_commands_are_real_numbers(bad):
    s = accd_gym.CaptureSim(calm=True)
    with pytest.raises(StateError, match="flap_commands_deg"):
        s.step(bad)
    assert s.time == 0.0
    s.step(np.array([1.0, -1.0, 0.5, 0.0], np.float32))
    s.step([np.float64(1.0), 2, 0, 0])


# 8. Errors a user can read -------------------------------------------------------------------


@pytest.mark.parametrize(
    "overrides, words",
    [
        ({"capture_window": float("nan")}, ["`capture_window`", "nan"]),
        ({"capture_window": "long"}, ["`capture_window`", '"long"', "invalid type"]),
        ({"tether": {"segments": "many"}}, ["`tether.segments`", "many"]),
        ({"reward": {"capture": [1]}}, ["`reward.capture`"]),
        ({"initial": {"offset": [1.0, float("inf")]}}, ["`initial.offset[1]`"]),
        ({"wake_seed": -3}, ["`wake_seed`", "-3"]),
    ],
)
def test_env_config_errors_name_the_field(overrides, words):
    with pytest.raises(ConfigError) as info:
        accd_gym.env_config(**overrides)
    for w in words:
        assert w in str(info.value), str(info.value)
    assert "line 1 column" not in str(info.value)


# 7. Self-contained configurations -----------------------------------------------------------


def test_a_config_with_a_user_aero_table_can_carry_the_table(tmp_path):
    from accd_gym.envs.config import self_contained

    path = tmp_path / "table.json"
    path.write_text(accd_gym.default_aero_table_json())
    by_path = accd_gym.env_config(accd={"aero_table": str(path)}, **SHORT)
    inline = self_contained(by_path)
    assert inline["accd"]["aero_table"].startswith("{") and by_path["accd"]["aero_table"] == str(path)
    path.unlink()  # the inline config needs no file
    a = accd_gym.CaptureSim({"accd": {"aero_table": inline["accd"]["aero_table"]}}, calm=True, seed=2)
    b = accd_gym.CaptureSim(calm=True, seed=2)
    sa, sb = a.step([3.0, -3.0, 1.0, 0.0], steps=30), b.step([3.0, -3.0, 1.0, 0.0], steps=30)
    assert np.allclose(sa["position"], sb["position"], rtol=0, atol=1e-9)
    with pytest.raises(ConfigError, match="aero_table"):
        self_contained(by_path)


def test_an_inline_table_that_is_broken_names_the_table():
    with pytest.raises(ConfigError, match="inline"):
        accd_gym.CaptureSim({"accd": {"aero_table": '{"alpha_deg": [1]}'}}, calm=True)


# 8. The command line ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, words",
    [
        (["train", "--config", "{cfg_array}", "--out", "{tmp}/run"], ["JSON list", "object"]),
        (["train", "--config", "{cfg_kwarg}", "--out", "{tmp}/run"], ["algo_kwargs", "learning_rat"]),
        (["train", "--config", "{cfg_seed}", "--out", "{tmp}/run"], ["`seed`"]),
        (["train", "--config", "{cfg_ok}", "--out", "/proc/no/such/dir"], ["--out", "/proc/no/such/dir"]),
        (["train", "--resume", "{tmp}/nothing"], ["not a run folder"]),
        (["train", "--config", "{tmp}/missing.json", "--out", "{tmp}/run"], ["does not exist"]),
        (["evaluate", "--policy", "zero", "--episodes", "1", "--out", "/proc/no/such/dir", "--quiet"], ["/proc/no"]),
        (["rollout", "--policy", "zero", "--env", "[1, 2]", "--quiet"], ["--env", "JSON object"]),
        (["rollout", "--policy", "zero", "--env", '{"capture_window": "x"}', "--quiet"], ["capture_window"]),
        (["rollout", "--policy", "zero", "--num-envs", "100000", "--episodes", "100000", "--quiet"], ["num_envs"]),
        (["evaluate", "--policy", "{tmp}", "--episodes", "1", "--quiet"], ["no final model"]),
        (["train", "--config", "{cfg_arch}", "--out", "{tmp}/run"], ["`policy_kwargs.net_arch`", "'x'"]),
        (["train", "--config", "{cfg_lr}", "--out", "{tmp}/run"], ["PPO refused", "learning_rate", "'x'"]),
    ],
)
def test_cli_user_errors_exit_2_on_one_line(argv, words, tmp_path, capsys):
    import json as _json

    from accd_gym.cli import main

    files = {"cfg_array": [1, 2], "cfg_kwarg": {"algo_kwargs": {"learning_rat": 1}},
             "cfg_seed": {"seed": True}, "cfg_ok": {"total_timesteps": 8},
             "cfg_arch": {"total_timesteps": 8, "policy_kwargs": {"net_arch": "x"}},
             "cfg_lr": {"total_timesteps": 8, "num_envs": 2, "algo_kwargs": {"learning_rate": "x"},
                        "env": {"initial": {"settle_time": 20.0}}}}
    for name, doc in files.items():
        (tmp_path / f"{name}.json").write_text(_json.dumps(doc))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    argv = [str(tmp_path / f"{a[1:-1]}.json") if a[1:-1] in files else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("accd-gym: error:"), err
    for w in words:
        assert w in err, err


@pytest.mark.parametrize("argv", [["evaluate", "--policy", "zero", "--num-threads", "-1"],
                                  ["rollout", "--policy", "zero", "--seed", "-5"],
                                  ["settle", "--duration", "-1"], ["settle", "--duration", "nan"]])
def test_cli_bad_option_values_are_argparse_errors(argv, capsys):
    from accd_gym.cli import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert "outside the allowed range" in err
    assert err.count("\n") == 0 and err.startswith(f"accd-gym {argv[0]}: error:") and "--help" in err, err


@pytest.mark.parametrize("argv", [[], ["nosuch"], ["study", "nosuch"], ["train", "--bogus"]])
def test_cli_parse_errors_are_one_line(argv, capsys):
    from accd_gym.cli import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and ": error: " in err, err


@pytest.mark.parametrize("seed", ["12", 1.9, True, [1, 2], -1])
def test_sb3_vec_env_seeds_are_integers(seed):
    # reset(seed="12") seeded [1, 2]
    with pytest.raises(ConfigError, match="seed"):
        accd_gym.AccdVecEnv(num_envs=2, seed=seed, **SHORT)
    env = accd_gym.AccdVecEnv(num_envs=2, seed=np.int64(3), num_threads=1, **SHORT)
    with pytest.raises(ConfigError, match="seed"):
        env.seed(seed)
        env.reset()
    assert np.array_equal(env.reset(), accd_gym.AccdVecEnv(num_envs=2, seed=3, num_threads=1, **SHORT).reset())


# 9. The supported Python versions are the tested ones ------------------------------------------


def test_the_oldest_python_claimed_is_the_one_ci_runs_and_the_sources_parse_on_it():
    """pyproject claims Python >= 3.11 and CI runs 3.11 (scripts/setup.sh's default ``python3`` is 3.11 there);
    every module of the package must parse as 3.11 syntax (no newer grammar slips in), and the
    README states the same bound."""
    import ast
    import pathlib
    import re
    import sys
    import tomllib

    root = pathlib.Path(__file__).resolve().parent.parent
    claim = tomllib.loads((root / "pyproject.toml").read_text())["project"]["requires-python"]
    oldest = tuple(int(x) for x in re.fullmatch(r">=\s*(\d+)\.(\d+)", claim).groups())
    assert oldest == (3, 11), claim
    assert sys.version_info[:2] >= oldest
    assert "Python >= 3.11" in (root / "README.md").read_text()
    files = sorted((root / "python" / "accd_gym").rglob("*.py"))
    assert len(files) > 10
    for path in files:
        ast.parse(path.read_text(), filename=str(path), feature_version=oldest)
