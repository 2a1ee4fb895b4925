"""The headless command line: `accd-gym settle` writes a plot and a summary."""

import json
import subprocess
import sys

import pytest

from accd_gym.studies import settle
from accd_gym.cli import main


def test_settle_writes_plot_and_summary(tmp_path):
    assert main(["settle", "--out", str(tmp_path), "--duration", "40", "--quiet"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["final_depth_m"] == pytest.approx(50.0, rel=0.15)
    assert 10.0 < summary["settling_time_s"] < 40.0
    png = (tmp_path / "settle.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000
    assert (tmp_path / "history.npz").exists()


def test_settle_reports_bad_preset_cleanly(tmp_path, capsys):
    assert main(["settle", "--out", str(tmp_path), "--preset", "nylon-1m-1mm", "--quiet"]) == 2
    assert "preset" in capsys.readouterr().err


def test_module_entry_point_help():
    out = subprocess.run([sys.executable, "-m", "accd_gym", "--help"], capture_output=True, text=True, check=True)
    assert "settle" in out.stdout


def test_settling_time_definition():
    import numpy as np

    t = np.arange(10.0)
    z = np.array([0, 10, 20, 15, 11, 10.1, 10, 10, 10, 10.0])
    assert settle.settling_time(t, z, band=0.02) == 5.0


def test_ctrl_c_after_the_command_finished_is_ignored_at_shutdown(tmp_path):
    """A SIGINT that arrives while the interpreter shuts down (after the command returned) leaves
    the exit code and prints no traceback: the executable ignores Ctrl+C once its work is done."""
    script = (
        "import atexit, os, signal, time\n"
        "def late_interrupt():\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "    time.sleep(0.2)  # Python code running after the signal: where a KeyboardInterrupt would land\n"
        "atexit.register(late_interrupt)\n"
        "import sys\n"
        f"sys.argv = ['accd-gym', 'export-aero', '--out', {str(tmp_path / 'aero.json')!r}]\n"
        "from accd_gym.cli import run\n"
        "run()\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr and "KeyboardInterrupt" not in out.stderr, out.stderr
    assert (tmp_path / "aero.json").stat().st_size > 0
