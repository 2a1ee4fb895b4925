"""No traceback from any argument: every command-line option and every config value, however
large, deep, long or malformed, ends in one line naming the option (or, inside ``--env``, the
config key) and exit code 2.

The cases the fault suite missed are tests of their own; a hypothesis property then drives the
command line in this process (:func:`accd_gym.cli.main`, fast: every value is refused before any
work) with generated odd values for every option.
"""

from __future__ import annotations

import json
import os
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from accd_gym.cli import main

settings.register_profile("cli", deadline=None, derandomize=True, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def run_cli(args: list[str], capsys) -> tuple[int, str]:
    """``accd-gym ARGS`` in this process: the exit code (argparse's SystemExit included) and stderr.
    An exception escaping :func:`main` is what a user would see as a traceback: it fails the test."""
    capsys.readouterr()
    try:
        code = main(args)
    except SystemExit as e:
        code = e.code
    except BaseException as e:  # noqa: BLE001 - a traceback is the failure under test
        pytest.fail(f"accd-gym {_show(args)} raised {type(e).__name__}: {str(e)[:300]}")
    return code, capsys.readouterr().err


def _show(args: list[str]) -> str:
    return " ".join(a if len(a) < 60 else a[:57] + "..." for a in args)


def assert_refused(args: list[str], names: list[str], capsys) -> str:
    """Runs ``args``; asserts exit 2, no traceback and one error line naming one of ``names``."""
    code, err = run_cli(args, capsys)
    assert code == 2, (_show(args), code, err[-2000:])
    assert "Traceback" not in err, err[-3000:]
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1, err[-2000:]
    assert any(n in lines[0] for n in names), (names, lines[0][:500])
    return lines[0]


# -- the cases of the fault report ------------------------------------------------------------------


def test_settle_with_a_duration_of_1e308_is_refused_in_one_line(capsys):
    line = assert_refused(["settle", "--duration", "1e308", "--quiet"], ["--duration"], capsys)
    assert "(0, 3600] s" in line


def test_an_env_nested_30000_deep_is_refused_in_one_line(capsys, tmp_path):
    deep = "[" * 30_000 + "]" * 30_000
    for text in (deep, '{"a": ' + deep + "}", '{"capture_window": ' * 30_000 + "1" + "}" * 30_000):
        line = assert_refused(["evaluate", "--policy", "zero", "--episodes", "2", "--out", str(tmp_path / "e"),
                               "--quiet", "--env", text], ["--env"], capsys)
        assert len(line) < 600, len(line)
    assert not (tmp_path / "e" / "results.json").exists()


def test_an_env_with_a_5000_digit_number_is_refused_in_one_line(capsys):
    assert_refused(["rollout", "--policy", "zero", "--episodes", "1", "--quiet",
                    "--env", '{"capture_window": ' + "9" * 5000 + "}"], ["--env"], capsys)


@pytest.mark.parametrize("field", ["accd.aero_table", "wake.tables.low"])
def test_a_table_path_with_a_nul_character_is_refused_in_one_line(field, capsys):
    env = {"accd": {"aero_table": "a\0b.json"}} if field == "accd.aero_table" else \
        {"wake": {"tables": {"low": "a\0b.json", "high": "a\0b.json"}}}
    line = assert_refused(["rollout", "--policy", "zero", "--episodes", "1", "--quiet", "--env", json.dumps(env)],
                          [field], capsys)
    assert "NUL" in line or "null" in line, line


@pytest.mark.parametrize("option", ["--out", "--config"])
def test_a_path_with_a_nul_character_or_empty_is_refused_in_one_line(option, capsys):
    for value in ("a\0b", ""):
        assert_refused(["train", option, value, *(["--out", "x"] if option == "--config" else []), "--quiet"],
                       [option], capsys)


# -- every option with generated odd values -----------------------------------------------------------


def _not_an_integer(text: str) -> bool:
    return re.fullmatch(r"\s*[+-]?[0-9_]+\s*", text) is None


#: Text no integer option takes: anything that is not an integer, and integers far outside
#: every range (huge, negative, with thousands of digits).
odd_integers = st.one_of(
    st.sampled_from(["", " ", "nan", "inf", "-inf", "1e308", "1.5", "0x10", "٣", "²", "1\0", "\0", "--3", "+-3",
                     "9" * 5000, "-" + "9" * 400, "1" + "0" * 30]),
    st.integers(min_value=2**63, max_value=10**400).map(str),  # beyond every count and seed
    st.integers(max_value=-1).map(str),
    st.text(max_size=30).filter(_not_an_integer),
)

#: Text no seconds option takes: not a number, not finite, not positive, or longer than its bound.
odd_seconds = st.one_of(
    st.sampled_from(["", "nan", "-nan", "inf", "1e308", "-0", "0", "1e-400", "3600.0001", "1e4000", "\0"]),
    st.floats(max_value=0.0).map(repr),
    st.floats(min_value=3600.001, allow_infinity=True).map(repr),
    st.text(max_size=20).filter(lambda t: re.fullmatch(r"\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*", t) is None),
)

#: Text no path option takes.
odd_paths = st.sampled_from(["", "\0", "a\0b", "runs/\0/x"])


def _deep(depth: int, kind: str) -> str:
    if kind == "list":
        return "[" * depth + "]" * depth
    return '{"a": ' * depth + "1" + "}" * depth


#: --env texts that are not a usable config: malformed JSON, not an object, nested too deeply to
#: read, numbers of thousands of digits, unknown keys, values of the wrong type or out of range.
odd_env = st.one_of(
    st.sampled_from(["{", "[]", "1", "null", '"x"', "{'a': 1}", '{"capture_window": 1e999}',
                     '{"capture_window": -1}', '{"capture_window": 0}', '{"capture_window": "70"}',
                     '{"capture_window": null}', '{"capture_window": [1]}', '{"tether": {"time_step": 1e-12}}',
                     '{"tether": 3}', '{"nope": 1}', '{"accd": {"mass": 1e300}}', '{"accd": {"mass": -1}}',
                     '{"wake_seed": -1}', '{"wake_seed": 1.5}', '{"wake_seeds": []}', '{"wake_seeds": [-1]}',
                     '{"agent_step": 0.123456789}', '{"initial": {"settle_time": 1e9}}']),
    st.builds(_deep, st.integers(min_value=200, max_value=50_000), st.sampled_from(["list", "object"])),
    st.integers(min_value=5000, max_value=20_000).map(lambda n: '{"capture_window": ' + "7" * n + "}"),
    st.integers(min_value=2**63, max_value=2**80).map(lambda s: json.dumps({"wake_seed": s})),
    st.text(max_size=40).map(lambda t: json.dumps({t + "_unknown": 1})),
)

#: (command and the options it needs, the option, its odd values, what else than the option the
#: error line may name: the config key inside --env, the policy's description)
OPTIONS = [
    (["settle", "--quiet"], "--duration", odd_seconds, None),
    (["settle", "--quiet"], "--out", odd_paths, None),
    (["study", "fig9", "--quiet"], "--dpi", odd_integers, None),
    (["study", "fig9", "--quiet"], "--out", odd_paths, None),
    (["export-aero"], "--out", odd_paths, None),
    (["train", "--out", "runs/never", "--quiet"], "--timesteps", odd_integers, None),
    (["train", "--out", "runs/never", "--quiet"], "--seed", odd_integers, None),
    (["train", "--out", "runs/never", "--quiet"], "--config", odd_paths, None),
    (["train", "--quiet"], "--resume", odd_paths, None),
    (["distill", "--out", "runs/never", "--quiet"], "--seed", odd_integers, None),
    (["distill", "--out", "runs/never", "--quiet"], "--config", odd_paths, None),
    (["distill", "--quiet"], "--resume", odd_paths, None),
    (["evaluate", "--policy", "zero", "--quiet"], "--episodes", odd_integers, None),
    (["evaluate", "--policy", "zero", "--quiet"], "--num-envs", odd_integers, None),
    (["evaluate", "--policy", "zero", "--quiet"], "--num-threads", odd_integers, None),
    (["evaluate", "--policy", "zero", "--quiet"], "--replay", odd_integers, None),
    (["evaluate", "--policy", "zero", "--quiet"], "--out", odd_paths, None),
    (["evaluate", "--policy", "zero", "--ray", "--quiet"], "--ray-chunk", odd_integers, None),
    (["replay", "--policy", "zero", "--quiet"], "--seed", odd_integers, None),
    (["replay", "--policy", "zero", "--quiet"], "--only", odd_integers, None),
    (["replay", "--policy", "zero", "--quiet"], "--max-frames", odd_integers, None),
    (["sweep", "--quiet"], "--config", odd_paths, None),
    (["benchmark", "--quiet"], "--seeds", odd_integers.filter(lambda t: "," not in t and t.strip() != ""), None),
    (["benchmark", "--quiet"], "--docs", odd_paths, None),
    (["rollout", "--policy", "zero", "--episodes", "1", "--quiet"], "--seed", odd_integers, None),
    (["rollout", "--policy", "zero", "--episodes", "1", "--quiet"], "--env", odd_env, ["invalid config", "`"]),
    (["rollout", "--episodes", "1", "--quiet"], "--policy",
     st.one_of(odd_paths, st.text(max_size=30).filter(lambda t: t.strip() not in ("zero", "random", "guidance", "lqr"))),
     ["policy"]),
]


@settings(settings.get_profile("cli"), max_examples=int(os.environ.get("ACCD_CLI_EXAMPLES", "300")))
@given(case=st.sampled_from(range(len(OPTIONS))).flatmap(
    lambda i: st.tuples(st.just(i), OPTIONS[i][2])))
def test_every_option_with_an_odd_value_ends_in_one_line_and_exit_2(case, capsys, tmp_path_factory, monkeypatch):
    i, value = case
    command, option, _, names = OPTIONS[i]
    monkeypatch.chdir(tmp_path_factory.getbasetemp())
    # "--opt=value": a value starting with "-" is the option's, not another option
    args = [*command, f"{option}={value}"]
    expected = [option] if names is None else [option, *names]
    assert_refused(args, expected, capsys)
