"""Constructing an env ends in seconds, and every failure to construct one names its field(s).

* Bounded set-up: settling the open-loop equilibrium takes ``initial.settle_time /
  tether.time_step`` physics steps; more than ``MAX_SETTLE_STEPS`` (2e5) is refused at once
  with the reason and the limit (``tether.time_step = 1e-7`` ran for minutes).
* A value inside its documented range that cannot give a valid simulation is a ConfigError
  naming the field(s): the reported ``accd.mass = 0.01`` and ``accd.diameter = 1e-300``, a gust
  history too long for a slow ``aircraft.airspeed``, and random in-range configurations.
"""

from __future__ import annotations

import json
import math
import re
import time

import numpy as np
import pytest

import accd_gym
from accd_gym import AccdError, ConfigError, _core
from accd_gym.cli import main
from accd_gym.envs.config import default_config

QUICK = dict(capture_window=2.0)


def test_a_time_step_of_1e_7_is_refused_in_seconds_with_the_reason_and_the_limit():
    t0 = time.monotonic()
    with pytest.raises(ConfigError) as e:
        accd_gym.InAirCaptureEnv(tether={"time_step": 1e-7}, **QUICK)
    text = str(e.value)
    assert "`tether.time_step` = 0.0000001" in text or "`tether.time_step` = 1e-7" in text, text
    assert "initial.settle_time" in text and "4.000e8" in text and "at most 2e5" in text, text
    assert time.monotonic() - t0 < 5
    with pytest.raises(ConfigError, match=r"tether.time_step.*\[2e-4, 1\] s"):
        accd_gym.InAirCaptureVectorEnv(2, tether={"time_step": 1e-4}, **QUICK)


def test_the_cli_refuses_a_time_step_of_1e_7_in_one_line_within_seconds(capsys):
    t0 = time.monotonic()
    code = main(["rollout", "--policy", "zero", "--episodes", "1", "--num-envs", "1", "--quiet",
                 "--env", json.dumps({"tether": {"time_step": 1e-7}})])
    assert code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "tether.time_step" in err, err
    assert time.monotonic() - t0 < 10


@pytest.mark.parametrize("field, value", [("accd.mass", 0.01), ("accd.diameter", 1e-300)])
def test_an_in_range_value_that_cannot_settle_is_a_config_error_naming_it(field, value):
    section, key = field.split(".")
    with pytest.raises(ConfigError) as e:
        accd_gym.InAirCaptureEnv(**{section: {key: value}}, **QUICK)
    assert f"{field} = " in str(e.value), str(e.value)


def test_a_gust_history_too_long_for_a_slow_airspeed_names_the_airspeed():
    with pytest.raises(ConfigError) as e:
        accd_gym.InAirCaptureEnv(aircraft={"airspeed": 0.3}, **QUICK)
    text = str(e.value)
    assert "turbulence.history_distance_m" in text and "aircraft.airspeed = 0.3 m/s" in text, text


# -- random in-range configurations -----------------------------------------------------------------

_RANGE = re.compile(r"^([\[(])\s*([-+0-9.e]+)\s*,\s*([-+0-9.e]+)\s*([\])])$")


def _numeric_fields() -> list[tuple[str, float, float, bool]]:
    """``(dotted key, low, high, integer)`` of every number field with a finite declared range,
    read from the declarations (``_core.config_fields``), its open ends moved inside."""
    defaults = default_config()
    out = []
    for key, _unit, allowed, _description, section, _declared in _core.config_fields():
        m = _RANGE.match(allowed.strip())
        if section or not m:
            continue
        value = defaults
        for part in key.split("."):
            value = value.get(part) if isinstance(value, dict) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        low, high = float(m.group(2)), float(m.group(3))
        if m.group(1) == "(":
            low = low * (1 + 1e-9) if low > 0 else (high * 1e-9 if low == 0 else low + 1e-9 * (high - low))
        if m.group(4) == ")":
            high -= 1e-9 * (high - low)
        out.append((key, low, high, isinstance(value, int)))
    return out


def _draw(rng: np.random.Generator, low: float, high: float, integer: bool) -> float:
    """A value in [low, high]: uniform, or log-uniform over the decades a wide positive range spans."""
    if integer:
        return int(rng.integers(math.ceil(low), math.floor(high) + 1))
    if low > 0 and high / low > 100 and rng.random() < 0.7:
        return float(math.exp(rng.uniform(math.log(low), math.log(high))))
    return float(rng.uniform(low, high))


def _nested(values: dict[str, float]) -> dict:
    out: dict = {}
    for key, value in values.items():
        *path, last = key.split(".")
        d = out
        for part in path:
            d = d.setdefault(part, {})
        d[last] = value
    return out


#: How many random configurations; each builds an env (its equilibrium settled): about a second.
RANDOM_CONFIGS = 24


def test_every_failure_of_a_random_in_range_configuration_names_a_changed_field():
    fields = [f for f in _numeric_fields()
              # the set-up cost grows as 1 / tether.time_step (the bound has its own test above)
              if f[0] not in ("tether.time_step",)]
    assert len(fields) > 40, len(fields)
    rng = np.random.default_rng(44)
    failures = []
    for _ in range(RANDOM_CONFIGS):
        picked = rng.choice(len(fields), size=int(rng.integers(1, 4)), replace=False)
        values = {fields[i][0]: _draw(rng, *fields[i][1:]) for i in picked}
        try:
            env = accd_gym.InAirCaptureEnv(**{**QUICK, **_nested(values)})
        except AccdError as e:
            text = str(e)
            failures.append(text)
            assert any(key in text for key in values), f"{values}: {text}"
        else:
            env.close()
    assert failures, "no random configuration failed: the test shows nothing"
