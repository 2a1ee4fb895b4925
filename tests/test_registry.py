"""The one Policy interface and the one registry: every controller, shipped policy and model path
resolves through :func:`accd_gym.evals.policies.load_policy`, and a controller registered in one
place runs in every path that takes a policy (evaluation, recording, the benchmark's baselines,
the residual base, the command line)."""

from __future__ import annotations

import json
import pickle
from typing import Any, Mapping, Optional

import numpy as np
import pytest

from accd_gym.cli import main
from accd_gym.control import registry
from accd_gym.control.baselines import GuidancePolicy, RandomPolicy, ZeroPolicy
from accd_gym.control.lqr import LqrPolicy
from accd_gym.control.registry import CONTROLLERS, Controller, Policy, make_controller, register_controller
from accd_gym.envs.residual import ResidualOptions
from accd_gym.envs.task import observation_indices
from accd_gym.envs.vector import InAirCaptureVectorEnv
from accd_gym.errors import ConfigError
from accd_gym.evals import benchmark
from accd_gym.evals.episodes import run_episodes
from accd_gym.evals.policies import load_policy
from accd_gym.replays.recording import record_episodes

SHORT = {"capture_window": 2.0}
_ERROR = observation_indices("boom_rel_y", "boom_rel_z")


class BangBang:
    """Full pitch and yaw towards the boom (the worked example of docs/architecture.md)."""

    name = "bang_bang"

    def predict(self, obs: Any) -> np.ndarray:
        e = np.asarray(obs, dtype=np.float32)[:, _ERROR]
        pitch, yaw = -np.sign(e[:, 1]), np.sign(e[:, 0])
        return np.stack([pitch, pitch, yaw, yaw], axis=1).astype(np.float32)

    def reset(self, mask: Optional[np.ndarray] = None) -> None:
        pass

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: Mapping[str, np.ndarray]) -> None:
        pass


@pytest.fixture
def bang_bang():
    """BangBang registered for one test (removed from the registry after it)."""
    register_controller(Controller("bang_bang", lambda seed, config: BangBang(), "full flaps towards the boom"))
    yield "bang_bang"
    CONTROLLERS.pop("bang_bang")


def test_every_built_in_controller_is_a_policy_and_pickles_alike():
    assert list(CONTROLLERS) == ["zero", "random", "guidance", "lqr", "mpc"]
    assert registry.residual_bases() == ["guidance", "lqr", "mpc"]
    kinds = {"zero": ZeroPolicy, "random": RandomPolicy, "guidance": GuidancePolicy, "lqr": LqrPolicy}
    obs = np.random.default_rng(1).uniform(-1, 1, (3, 25)).astype(np.float32)
    for name, cls in kinds.items():
        policy = load_policy(name, seed=4)
        assert type(policy) is cls and isinstance(policy, Policy), name
        policy.predict(obs)
        copy = pickle.loads(pickle.dumps(policy))
        np.testing.assert_array_equal(policy.predict(obs), copy.predict(obs))
        state = policy.get_state()
        assert all(np.shape(v)[0] == 3 for v in state.values()), name
        policy.set_state(state)


def test_the_resolver_and_make_controller_give_the_same_episodes():
    a = run_episodes(load_policy("random", seed=3, config=SHORT), 3, num_envs=3, config=SHORT)
    b = run_episodes(make_controller("random", 3, SHORT), 3, num_envs=3, config=SHORT)
    assert [e.metrics() for e in a] == [e.metrics() for e in b]


def test_unknown_and_clashing_names_are_config_errors_naming_the_registry():
    with pytest.raises(ConfigError, match=r"'autopilot'.*'zero', 'random', 'guidance', 'lqr'"):
        load_policy("autopilot")
    with pytest.raises(ConfigError, match="'autopilot' is outside the allowed range"):
        make_controller("autopilot")
    with pytest.raises(ConfigError, match="already registered"):
        register_controller(Controller("zero", lambda seed, config: ZeroPolicy(), "again"))
    for bad in ("a/b", "x.json", ""):
        with pytest.raises(ConfigError, match="controller name"):
            register_controller(Controller(bad, lambda seed, config: ZeroPolicy(), "bad"))
    assert list(CONTROLLERS) == ["zero", "random", "guidance", "lqr", "mpc"]


def test_a_registered_controller_runs_everywhere_a_policy_is_taken(bang_bang, capsys):
    policy = load_policy(bang_bang)
    assert isinstance(policy, BangBang)
    evaluated = run_episodes(policy, 2, num_envs=2, config=SHORT)
    (recorded,) = record_episodes(bang_bang, 2, keep=[1], num_envs=2, config=SHORT)
    assert recorded.meta["policy"] == bang_bang
    assert evaluated[1].steps == recorded.arrays["reward"].shape[0]
    np.testing.assert_array_equal(np.abs(recorded.arrays["action"]), 1.0)
    cfg = benchmark.validate_config({"tiers": ["nominal"], "baselines": ["zero", bang_bang], "learners": {}})
    assert cfg["baselines"] == ["zero", bang_bang]
    assert isinstance(benchmark._baseline_policy(bang_bang, "nominal"), BangBang)
    assert main(["rollout", "--policy", bang_bang, "--episodes", "1", "--num-envs", "1", "--num-threads", "1",
                 "--env", json.dumps(SHORT), "--quiet", "--json"]) == 0
    assert f"{bang_bang}: " in capsys.readouterr().out
    with pytest.raises(ConfigError, match="residual.base"):
        ResidualOptions.parse({"base": bang_bang})  # not registered as a residual base


def test_a_controller_registered_as_a_residual_base_drives_the_residual_option(monkeypatch):
    monkeypatch.setitem(CONTROLLERS, "bang_bang", Controller("bang_bang", lambda seed, config: BangBang(), "full flaps",
                                                             residual_base=True))
    assert ResidualOptions.parse("bang_bang").base == "bang_bang"
    env = InAirCaptureVectorEnv(2, residual={"base": "bang_bang", "scale": 0.3, "observe_base": True}, **SHORT)
    obs, _ = env.reset(seed=5)
    base = obs[:, -4:]  # the base command observed
    np.testing.assert_array_equal(base, BangBang().predict(obs[:, :25]))
    env.close()
