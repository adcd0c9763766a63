"""The `sketchrodgs` command: help, info, exit codes."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from sketchrodgs.cli import SUBCOMMANDS, build_parser, main


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "sketchrodgs", *args], capture_output=True, text=True, timeout=120)


def test_console_script_is_installed():
    # the script sits beside the interpreter of the environment the package is installed in
    exe = shutil.which(
        "sketchrodgs", path=os.pathsep.join([os.path.dirname(sys.executable), os.environ.get("PATH", "")])
    )
    assert exe, "the sketchrodgs console script is not on PATH"
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.startswith("sketchrodgs ")


@pytest.mark.parametrize("command", [None, *SUBCOMMANDS])
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"] if command is None else [command, "--help"])
    assert info.value.code == 0
    assert "usage: sketchrodgs" in capsys.readouterr().out


def test_info_on_the_bundled_sample():
    result = run_cli("info", "sample:ring")
    assert result.returncode == 0, result.stderr
    assert "10,000" in result.stdout and "sh degree  0" in result.stdout
    summary = json.loads(run_cli("info", "sample:ring", "--json").stdout)
    assert summary["count"] == 10_000 and summary["format"] == "splat"
    assert summary["bbox_min"][0] == pytest.approx(-0.5, abs=1e-3)


def test_domain_error_is_one_line_and_exit_1(tmp_path):
    bad = tmp_path / "broken.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nend_header\n")
    result = run_cli("info", str(bad))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "broken.ply" in lines[0] and "Traceback" not in result.stderr


def test_usage_error_is_exit_2():
    assert run_cli("info").returncode == 2
    assert run_cli("info", "sample:nonexistent").returncode == 2
    assert build_parser().prog == "sketchrodgs"
