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


HEAVY = ("numpy", "scipy", "viser", "imageio", "PIL", "tqdm", "plyfile")


def modules_loaded_by(*args: str) -> set[str]:
    """The heavy top-level packages imported by `sketchrodgs ARGS` (a fresh interpreter)."""
    code = (
        "import sys\nfrom sketchrodgs.cli import main\n"
        f"try:\n    main({list(args)!r})\nexcept SystemExit:\n    pass\n"
        "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split()) & set(HEAVY)


def test_start_up_imports_only_what_the_command_needs():
    """`--version` and the help import none of the heavy libraries, `info` only numpy and the
    readers (start-up in about 0.1 s instead of 0.6 s)."""
    assert modules_loaded_by("--version") == set()
    assert modules_loaded_by("--help") == set()
    assert modules_loaded_by("render", "--help") == set()
    assert modules_loaded_by("info", "sample:ring") == {"numpy", "plyfile"}
    import sketchrodgs

    assert sketchrodgs.render.__module__ == "sketchrodgs.render" and callable(sketchrodgs.skin)  # lazily, by name


def test_every_public_name_resolves():
    import sketchrodgs

    assert set(sketchrodgs.__all__) == {*sketchrodgs._EXPORTS, "__version__", "data"}
    for name in sketchrodgs.__all__:
        assert getattr(sketchrodgs, name) is not None
    with pytest.raises(AttributeError):
        sketchrodgs.no_such_name  # noqa: B018
