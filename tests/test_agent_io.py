"""Residual control and observation history (accd_gym.envs.agent_io): a zero correction replays the
base controller bit for bit in every env class and tier, across automatic resets; the history's
fill rule and contents; spaces, the env checker, pickles and states; bad options refused."""

import pickle
import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from accd_gym import AccdVecEnv, ConfigError, InAirCaptureEnv, InAirCaptureVectorEnv, StateError
from accd_gym.envs.agent_io import AgentInterface, agent_io_markdown
from accd_gym.control.baselines import GuidancePolicy
from accd_gym.control.lqr import LqrPolicy
from accd_gym.envs.task import ACT_DIM, OBS_DIM

# Short episodes (truncated after 3 s = 30 steps), so that a rollout crosses automatic resets.
SHORT = dict(capture_window=3.0)
RESIDUAL = {"base": "lqr", "scale": 0.3}


def base_policy(base, env):
    return LqrPolicy.for_config(env.config) if base == "lqr" else GuidancePolicy()


@pytest.mark.parametrize("tier", ["nominal", "hard"])
@pytest.mark.parametrize("base", ["lqr", "guidance"])
def test_zero_correction_replays_the_base_controller_in_the_vector_env_across_autoresets(tier, base):
    n = 3
    plain = InAirCaptureVectorEnv(n, tier=tier, **SHORT)
    res = InAirCaptureVectorEnv(n, tier=tier, residual={"base": base, "scale": 0.3}, **SHORT)
    ctrl = base_policy(base, plain)
    obs, _ = plain.reset(seed=11)
    robs, _ = res.reset(seed=11)
    autoreset = np.zeros(n, dtype=bool)
    resets = 0
    for t in range(75):
        a = ctrl.predict(obs)
        assert np.array_equal(robs[:, :OBS_DIM], obs), t
        assert np.array_equal(robs[:, OBS_DIM:OBS_DIM + ACT_DIM], a), t  # the base command is observed
        obs, r, term, trunc, _ = plain.step(a)
        robs, rr, rterm, rtrunc, _ = res.step(np.zeros((n, ACT_DIM), np.float32))
        assert np.array_equal(rr, r) and np.array_equal(rterm, term) and np.array_equal(rtrunc, trunc), t
        if autoreset.any():  # these envs started new episodes in this step (next-step autoreset)
            ctrl.reset(autoreset)
            resets += 1
        autoreset = term | trunc
    assert resets >= 2


@pytest.mark.parametrize("tier", ["nominal", "hard"])
def test_zero_correction_replays_the_lqr_in_the_sb3_vec_env_and_its_terminal_observations(tier):
    n = 3
    plain = AccdVecEnv(n, seed=5, tier=tier, **SHORT)
    res = AccdVecEnv(n, seed=5, tier=tier, residual=RESIDUAL, history=2, **SHORT)
    lqr = LqrPolicy.for_config(plain.config)
    obs, robs = plain.reset(), res.reset()
    ended = 0
    for t in range(70):
        a = lqr.predict(obs)
        assert np.array_equal(robs[:, :OBS_DIM], obs) and np.array_equal(robs[:, OBS_DIM:OBS_DIM + ACT_DIM], a), t
        before = obs.copy()
        obs, r, dones, infos = plain.step(a)
        robs, rr, rdones, rinfos = res.step(np.zeros((n, ACT_DIM), np.float32))
        assert np.array_equal(rr, r) and np.array_equal(rdones, dones), t
        for i in np.flatnonzero(dones):
            ended += 1
            term = rinfos[i]["terminal_observation"]
            assert term.shape == res.observation_space.shape
            assert np.array_equal(term[:OBS_DIM], infos[i]["terminal_observation"])
            # the history of the last observation: the one before it, and the command sent
            assert np.array_equal(term[OBS_DIM + ACT_DIM:2 * OBS_DIM + ACT_DIM], before[i])
            commands = OBS_DIM + ACT_DIM + 2 * OBS_DIM  # history 2: the commands follow the observations
            assert np.array_equal(term[commands:commands + ACT_DIM], a[i])
        lqr.reset(dones)
    assert ended >= 3


@pytest.mark.parametrize("tier", ["nominal", "hard"])
def test_zero_correction_replays_the_lqr_in_the_single_env_and_the_wrapper(tier):
    plain = InAirCaptureEnv(tier=tier, **SHORT)
    native = InAirCaptureEnv(tier=tier, residual=RESIDUAL, **SHORT)
    wrapped = AgentInterface(InAirCaptureEnv(tier=tier, **SHORT), residual=RESIDUAL)
    lqr = LqrPolicy.for_config(plain.config)
    zero = np.zeros(ACT_DIM, np.float32)
    for episode in range(2):  # a second episode: the filter restarts with it
        obs, _ = plain.reset(seed=3 + episode)
        nobs, _ = native.reset(seed=3 + episode)
        wobs, _ = wrapped.reset(seed=3 + episode)
        lqr.reset()
        done = False
        while not done:
            a = lqr.predict(obs[None])[0]
            assert np.array_equal(nobs[:OBS_DIM], obs) and np.array_equal(nobs[OBS_DIM:], a)
            assert np.array_equal(wobs, nobs)
            obs, r, term, trunc, _ = plain.step(a)
            nobs, nr, *_ = native.step(zero)
            wobs, wr, *_ = wrapped.step(zero)
            assert nr == r == wr
            done = term or trunc


def test_the_correction_is_bounded_and_added_to_the_base_command():
    n = 2
    res = InAirCaptureVectorEnv(n, residual={"base": "lqr", "scale": 0.25}, history=1, **SHORT)
    obs, _ = res.reset(seed=0)
    for a in (np.full((n, ACT_DIM), 1.0, np.float32), np.full((n, ACT_DIM), -7.0, np.float32),
              np.array([[0.5, -0.5, 0.0, 2.0], [-1.0, 0.2, 0.4, -0.3]], np.float32)):
        base = obs[:, OBS_DIM:OBS_DIM + ACT_DIM]
        obs, *_ = res.step(a)
        sent = obs[:, -ACT_DIM:]  # history: the command sent in that step
        expected = np.clip(base + np.float32(0.25) * np.clip(a, -1, 1), -1, 1)
        assert np.array_equal(sent, expected)


def test_history_fill_rule_and_contents_across_autoresets():
    n, k = 2, 3
    env = InAirCaptureVectorEnv(n, history=k, **SHORT)
    assert env.single_observation_space.shape == (OBS_DIM + k * (OBS_DIM + ACT_DIM),)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=2)
    raw = [obs[:, :OBS_DIM].copy()]
    sent = []
    starts = np.zeros((n,), dtype=int)  # index in raw where each env's episode started
    autoreset = np.zeros(n, dtype=bool)
    for t in range(70):
        a = rng.uniform(-1.5, 1.5, (n, ACT_DIM)).astype(np.float32)
        obs, r, term, trunc, _ = env.step(a)
        raw.append(obs[:, :OBS_DIM].copy())
        sent.append(np.clip(a, -1, 1))
        starts[autoreset] = len(raw) - 1
        autoreset = term | trunc
        now = len(raw) - 1
        for i in range(n):
            for j in range(1, k + 1):
                past_o = obs[i, OBS_DIM * j:OBS_DIM * (j + 1)]
                past_a = obs[i, OBS_DIM * (k + 1) + ACT_DIM * (j - 1):OBS_DIM * (k + 1) + ACT_DIM * j]
                if now - j >= starts[i]:
                    assert np.array_equal(past_o, raw[now - j][i]) and np.array_equal(past_a, sent[now - j][i])
                else:  # before the episode's start: its first observation, zero commands
                    assert np.array_equal(past_o, raw[starts[i]][i]) and not past_a.any()
    assert starts.min() > 0  # both envs crossed an automatic reset


def test_history_alone_leaves_the_episodes_bit_for_bit():
    plain = InAirCaptureVectorEnv(2, tier="hard", **SHORT)
    hist = InAirCaptureVectorEnv(2, tier="hard", history=2, **SHORT)
    obs, _ = plain.reset(seed=4)
    hobs, _ = hist.reset(seed=4)
    rng = np.random.default_rng(1)
    for _ in range(40):
        assert np.array_equal(hobs[:, :OBS_DIM], obs)
        a = rng.uniform(-1, 1, (2, ACT_DIM)).astype(np.float32)
        obs, r, *_ = plain.step(a)
        hobs, hr, *_ = hist.step(a)
        assert np.array_equal(hr, r)


@pytest.mark.parametrize("autoreset_mode", [gym.vector.AutoresetMode.NEXT_STEP, gym.vector.AutoresetMode.SAME_STEP])
def test_native_vector_env_equals_sync_vector_env_of_single_envs(autoreset_mode):
    kw = dict(tier="hard", residual=RESIDUAL, history=2, **SHORT)
    native = InAirCaptureVectorEnv(2, autoreset_mode=autoreset_mode, **kw)
    sync = gym.vector.SyncVectorEnv([lambda: InAirCaptureEnv(**kw) for _ in range(2)],
                                    autoreset_mode=autoreset_mode)
    assert native.single_observation_space == sync.single_observation_space
    a_obs, _ = native.reset(seed=8)
    b_obs, _ = sync.reset(seed=8)
    rng = np.random.default_rng(3)
    for t in range(70):
        assert np.array_equal(a_obs, b_obs), t
        a = rng.uniform(-1, 1, (2, ACT_DIM)).astype(np.float32)
        a_obs, ar, at, atr, ai = native.step(a)
        b_obs, br, bt, btr, bi = sync.step(a)
        assert np.array_equal(ar, br) and np.array_equal(at, bt) and np.array_equal(atr, btr)
        if "final_obs" in bi:
            for i in np.flatnonzero(bi["_final_obs"]):
                assert np.array_equal(ai["final_obs"][i], bi["final_obs"][i])


def test_spaces_and_the_gymnasium_env_checker():
    from gymnasium.utils.env_checker import check_env

    env = InAirCaptureEnv(residual=RESIDUAL, history=3, **SHORT)
    assert env.observation_space.shape == (OBS_DIM + ACT_DIM + 3 * (OBS_DIM + ACT_DIM),)
    assert env.action_space.shape == (ACT_DIM,)
    check_env(env, skip_render_check=True)
    check_env(AgentInterface(InAirCaptureEnv(**SHORT), history=2), skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    no_base = InAirCaptureEnv(residual={"base": "lqr", "observe_base": False}, **SHORT)
    assert no_base.observation_space.shape == (OBS_DIM,)
    vec = gym.make_vec("accd_gym/InAirCaptureHard-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       residual=RESIDUAL, history=1)
    obs, _ = vec.reset(seed=0)
    assert vec.observation_space.contains(obs) and obs.shape == (2, OBS_DIM + ACT_DIM + OBS_DIM + ACT_DIM)
    assert vec.unwrapped.agent_options.to_dict() == {"residual": {**RESIDUAL, "observe_base": True}, "history": 1}


@pytest.mark.parametrize("kind", ["vector", "sb3", "single"])
def test_pickles_and_states_continue_bit_for_bit_across_autoresets(kind):
    kw = dict(tier="hard", residual=RESIDUAL, history=2, **SHORT)
    make = {"vector": lambda: InAirCaptureVectorEnv(2, **kw), "sb3": lambda: AccdVecEnv(2, seed=1, **kw),
            "single": lambda: InAirCaptureEnv(**kw)}[kind]
    env = make()
    shape = (ACT_DIM,) if kind == "single" else (2, ACT_DIM)
    env.reset() if kind == "sb3" else env.reset(seed=1)
    rng = np.random.default_rng(0)

    def step(e, a):
        out = e.step(a)
        if kind == "single" and (out[2] or out[3]):
            e.reset()
        return out

    for _ in range(17):
        step(env, rng.uniform(-1, 1, shape).astype(np.float32))
    copy = pickle.loads(pickle.dumps(env))
    restored = make()
    restored.set_state(env.get_state())
    for t in range(50):
        a = rng.uniform(-1, 1, shape).astype(np.float32)
        outs = [step(e, a) for e in (env, copy, restored)]
        for other in outs[1:]:
            assert np.array_equal(outs[0][0], other[0]) and np.array_equal(outs[0][1], other[1]), t


def test_states_of_other_options_or_plain_envs_are_refused_and_change_nothing():
    env = InAirCaptureVectorEnv(2, residual=RESIDUAL, history=2, **SHORT)
    env.reset(seed=0)
    before = env.get_state()
    plain = InAirCaptureVectorEnv(2, **SHORT)
    plain.reset(seed=0)
    with pytest.raises(StateError, match="agent options"):
        env.set_state(plain.get_state())
    other = InAirCaptureVectorEnv(2, residual=RESIDUAL, history=3, **SHORT)
    other.reset(seed=0)
    with pytest.raises(StateError, match="history"):
        env.set_state(other.get_state())
    with pytest.raises(StateError):
        env.set_state(before[:-40])
    with pytest.raises(StateError):
        plain.set_state(before)
    assert env.get_state() == before


@pytest.mark.parametrize("kwargs, message", [
    ({"residual": {"scale": 5}}, r"`residual.scale` = 5 is outside the allowed range \(0, 2\]"),
    ({"residual": {"scale": 0.0}}, r"`residual.scale` = 0.0 is outside the allowed range"),
    ({"residual": {"scale": float("nan")}}, r"`residual.scale` = nan"),
    ({"residual": {"base": "pid"}}, r"`residual.base` = 'pid' is outside the allowed range: one of 'guidance', 'lqr'"),
    ({"residual": {"gain": 1}}, r"`residual` key\(s\) \['gain'\] outside the allowed set"),
    ({"residual": {"observe_base": 1}}, r"`residual.observe_base` = 1"),
    ({"residual": 3}, r"`residual` = 3 is outside the allowed range"),
    ({"history": -1}, r"`history` = -1 is outside the allowed range: an integer in \[0, 64\]"),
    ({"history": 2.0}, r"`history` = 2.0 is outside the allowed range"),
    ({"history": True}, r"`history` = True"),
    ({"history": 65}, r"`history` = 65"),
])
@pytest.mark.parametrize("cls", ["single", "vector", "sb3"])
def test_bad_options_are_refused_naming_field_value_and_range(kwargs, message, cls):
    make = {"single": lambda: InAirCaptureEnv(**kwargs), "vector": lambda: InAirCaptureVectorEnv(2, **kwargs),
            "sb3": lambda: AccdVecEnv(2, **kwargs)}[cls]
    with pytest.raises(ConfigError, match=message):
        make()


def test_the_environment_doc_carries_the_generated_option_and_layout_tables():
    doc = (Path(__file__).resolve().parents[1] / "docs" / "environment.md").read_text()
    section = re.search(r"<!-- generated: accd_gym\.envs\.agent_io\.agent_io_markdown\(\) -->\n(.*?)\n<!-- end generated -->",
                        doc, re.S)
    assert section and section.group(1) == agent_io_markdown()
    import accd_gym.envs.agent_io

    assert agent_io_markdown() in accd_gym.envs.agent_io.__doc__


def test_observation_names_follow_the_layout():
    from accd_gym.envs.agent_io import AgentOptions

    opts = AgentOptions.parse(RESIDUAL, 2)
    names = opts.observation_names()
    assert len(names) == opts.observation_space().shape[0]
    assert names[OBS_DIM:OBS_DIM + ACT_DIM] == ["base_right", "base_left", "base_top", "base_bottom"]
    assert names[OBS_DIM + ACT_DIM] == "boom_rel_x[t-1]" and names[-1] == "command_bottom[t-2]"


def test_the_lqr_filter_predicts_with_the_command_sent():
    """With a correction, the base command is that of an LQR whose filter is told the command
    actually sent (``LqrPolicy.sent``), not the one it proposed."""
    n = 2
    plain = InAirCaptureVectorEnv(n, **SHORT)
    res = InAirCaptureVectorEnv(n, residual=RESIDUAL, **SHORT)
    told, untold = LqrPolicy.for_config(plain.config), LqrPolicy.for_config(plain.config)
    obs, _ = plain.reset(seed=6)
    robs, _ = res.reset(seed=6)
    rng = np.random.default_rng(2)
    differs = False
    for t in range(25):  # within the first episode
        u = told.predict(obs)
        v = untold.predict(obs)
        assert np.array_equal(robs[:, OBS_DIM:OBS_DIM + ACT_DIM], u), t
        differs |= not np.array_equal(u, v)
        a = rng.uniform(-1, 1, (n, ACT_DIM)).astype(np.float32)
        sent = np.clip(u + np.float32(0.3) * a, -1, 1)
        told.sent(sent.astype(np.float64) - u.astype(np.float64))
        obs, *_ = plain.step(sent)
        robs, *_ = res.step(a)
        assert np.array_equal(robs[:, :OBS_DIM], obs), t
    assert differs  # the filter's input matters



@pytest.mark.parametrize("kind", ["residual", "history"])
def test_a_policy_told_the_commands_sent_continues_as_the_env_that_sent_them(kind):
    """``sent(offset)`` on a policy's agent side (a teacher whose student flew): its base
    controller's filter and its history continue exactly as those of the env that sent the
    commands, bit for bit; a policy not told keeps its own commands and drifts away."""
    from accd_gym.envs.agent_io import AgentOptions, PolicyAgentIO

    n = 3
    options = {"residual": RESIDUAL} if kind == "residual" else {"history": 3}
    env = InAirCaptureVectorEnv(n, **options, **SHORT)
    plain = InAirCaptureVectorEnv(n, **SHORT)
    told = PolicyAgentIO(AgentOptions.parse(**options), plain.config)
    untold = PolicyAgentIO(AgentOptions.parse(**options), plain.config)
    obs, _ = env.reset(seed=11)
    pobs, _ = plain.reset(seed=11)
    rng = np.random.default_rng(5)
    differs = False
    for t in range(20):  # within the first episode
        assert np.array_equal(told.observation(pobs), obs), t
        differs |= not np.array_equal(untold.observation(pobs), obs)
        zero = np.zeros((n, ACT_DIM), dtype=np.float32)
        own = told.command(zero)
        untold.command(zero)
        a = rng.uniform(-1, 1, (n, ACT_DIM)).astype(np.float32)
        sent = np.clip(obs[:, OBS_DIM:OBS_DIM + ACT_DIM] + np.float32(0.3) * a, -1, 1) if kind == "residual" else a
        told.sent(sent.astype(np.float64) - own.astype(np.float64))
        obs, *_ = env.step(a)
        pobs, *_ = plain.step(sent)
        assert np.array_equal(obs[:, :OBS_DIM], pobs), t
    assert differs
