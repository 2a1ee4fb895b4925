"""Every code block of README.md runs: the Python blocks as scripts, the shell blocks' `accd-gym`
commands through `python -m accd_gym`, and the install block names the package, the wheel
`scripts/wheel.sh` builds and the command `scripts/setup.sh` itself runs (the wheel itself is
installed and run by scripts/test.sh's wheel job). The generated sections of README.md match the declarations they come from, and its
results table and docs/benchmark.md the committed benchmark report."""

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
BLOCK = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)


def blocks(language: str) -> list[str]:
    """The README's fenced code blocks of one language, in order."""
    return [body for lang, body in BLOCK.findall(README) if lang == language]


def test_readme_has_only_runnable_block_languages():
    languages = {lang for lang, _ in BLOCK.findall(README)}
    assert languages <= {"python", "bash"}, f"README code blocks of untested languages: {languages}"
    assert blocks("python"), "README.md has no Python example"


def test_first_gym_make_is_on_the_first_screen():
    line = next(i for i, text in enumerate(README.splitlines(), 1) if "gym.make(" in text)
    assert line <= 40, f"the first gym.make is on line {line} of README.md"


@pytest.mark.parametrize("index", range(len(blocks("python"))))
def test_python_block_runs(index, tmp_path):
    code = blocks("python")[index]
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"README Python block {index} failed:\n{code}\n{out.stderr[-3000:]}"


def shell_commands() -> list[list[str]]:
    """Each command line of the README's bash blocks, comments stripped, `\\` continuations joined."""
    commands = []
    for body in blocks("bash"):
        text = body.replace("\\\n", " ")
        for line in text.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                commands.append(words)
    return commands


def test_install_block_is_what_setup_and_wheel_build_use():
    """The README's installs: the published name (pyproject.toml's), the wheel file that
    scripts/wheel.sh writes (this version, the stable-ABI tag maturin gives it), and the source
    install scripts/setup.sh runs, in that order."""
    import tomllib

    installs = [c for c in shell_commands() if c[:2] == ["pip", "install"]]
    assert len(installs) == 3, installs
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert installs[0] == ["pip", "install", project["name"]]
    wheel = installs[1][2]
    name = project["name"].replace("-", "_")
    assert wheel.startswith(f"dist/{name}-{project['version']}-cp311-abi3-") and wheel.endswith(".whl"), wheel
    assert project["requires-python"] == ">=3.11", "the wheel's abi3 tag is the lowest Python allowed"
    assert '"pyo3/abi3-py311"' in (ROOT / "crates" / "py" / "Cargo.toml").read_text()
    assert 'OUT="${1:-dist}"' in (ROOT / "scripts" / "wheel.sh").read_text()
    spec = installs[2][-1]
    assert installs[2][2:] == ["-e", spec] and spec.startswith(".["), installs[2]
    setup = (ROOT / "scripts" / "setup.sh").read_text()
    assert 'install -e ".[' in setup, "scripts/setup.sh does not install the package as the README says"


def test_cli_commands_run_in_order(tmp_path):
    """The README's `accd-gym` commands, one after the other in one folder (a later one may use
    what an earlier one wrote, as a user's would)."""
    env = dict(os.environ, MPLBACKEND="Agg")
    commands = [c for c in shell_commands() if c[0] == "accd-gym"]
    assert commands, "README.md shows no accd-gym command"
    for command in commands:
        # Training configs are named relative to the repository, as a user runs them from its root.
        args = [str(ROOT / a) if a.startswith("training/") else a for a in command[1:]]
        out = subprocess.run(
            [sys.executable, "-m", "accd_gym", *args], cwd=tmp_path, env=env, capture_output=True, text=True,
            timeout=900,
        )
        assert out.returncode == 0, f"{' '.join(command)} failed:\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}"


def test_every_shell_command_is_tested():
    tested = {"accd-gym", "pip"}
    assert {c[0] for c in shell_commands()} <= tested, "a README shell command that no test runs"


def test_results_table_and_report_are_what_the_committed_benchmark_writes():
    """README's results table and docs/benchmark.md are what `accd-gym benchmark --docs docs
    --readme README.md` writes from the committed benchmark folder's report document
    (runs/benchmark/benchmark.json), cell for cell."""
    from accd_gym.evals import benchmark

    doc = json.loads((ROOT / "runs" / "benchmark" / "benchmark.json").read_text())
    table = README.split(benchmark.README_BEGIN)[1].split(benchmark.README_END)[0].strip()
    assert table == benchmark.readme_table(doc), "README.md's results table is not the committed report's"
    assert (ROOT / "docs" / "benchmark.md").read_text() == benchmark.report_markdown(doc), \
        "docs/benchmark.md is not the committed report's"
