"""The task's tables (action, observation, reward, episode end) are declared once and generated
into README.md, docs/environment.md and the env docstrings; the generated sections are current."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import accd_gym
from accd_gym.envs import tables
from accd_gym.envs.config import default_config

ROOT = Path(__file__).resolve().parents[1]


def test_generated_sections_are_current():
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "regen_docs.py"), "--check"], capture_output=True, text=True
    )
    assert out.returncode == 0, f"run `python scripts/regen_docs.py`:\n{out.stdout}{out.stderr}"


def test_regenerate_refuses_a_name_that_is_no_function():
    with pytest.raises(ValueError, match=r"README: generated section accd_gym\.envs\.tables\.nope\(\) names no function"):
        tables.regenerate("<!-- generated: accd_gym.envs.tables.nope() -->\nold\n<!-- end generated -->", "README")


def test_a_stale_section_is_rewritten():
    text = "<!-- generated: accd_gym.envs.tables.action_table_markdown() -->\nold\n<!-- end generated -->"
    assert tables.regenerate(text) == text.replace("old", tables.action_table_markdown())


def test_tables_follow_the_configuration():
    """The numbers come from the configuration, not from text: another default shows up."""
    config = default_config()
    config["boom"]["capture_radius"] = 0.3
    config["reward"]["failure"] = 7.0
    assert "`boom.capture_radius` (0.3 m)" in tables.episode_end_table_markdown(config)
    assert "`boom.capture_radius` (0.5 m)" in tables.episode_end_table_markdown()
    assert "`reward.failure` (7)" in tables.reward_table_markdown(config)


def test_every_symbol_of_the_reward_is_a_configuration_key():
    keys = {row[0] for row in accd_gym._core.config_fields()}
    assert set(tables.REWARD_SYMBOLS.values()) <= keys
    used = {key for _, _, term_keys, _ in tables.REWARD_TERMS for key in term_keys}
    assert used <= set(tables.REWARD_SYMBOLS.values())


def test_episode_end_flags_are_the_info_keys_the_env_reports():
    env = accd_gym.InAirCaptureEnv()
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(4, np.float32))
    flags = {flag for _, _, flag in tables.EPISODE_END if flag != "-"}
    assert flags <= set(info), flags - set(info)
    assert all(isinstance(info[f], (bool, np.bool_)) for f in flags)


def test_action_rows_follow_the_action_space():
    env = accd_gym.InAirCaptureEnv()
    assert len(tables.ACTION_FLAPS) == env.action_space.shape[0]
    assert len(tables.observation_table_markdown().splitlines()) - 2 == env.observation_space.shape[0]


@pytest.mark.parametrize("cls", [accd_gym.InAirCaptureEnv])
def test_env_docstring_carries_the_tables(cls):
    lines = [line.strip() for line in cls.__doc__.splitlines()]
    for make in tables.TABLE_MARKERS.values():
        assert all(row.strip() in lines for row in make().splitlines() if row.strip()), make.__name__
    assert not any(line in tables.TABLE_MARKERS for line in lines)
