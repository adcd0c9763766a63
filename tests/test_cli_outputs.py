"""Outputs are checked before any work, a failed command leaves none behind, and errors name the
user's paths (never a staging or temporary file)."""

from __future__ import annotations

import errno
import json

import numpy as np
import pytest

from sketchrodgs import Camera, data
from sketchrodgs.cli import main
from sketchrodgs.cli._outputs import STAGING_PREFIX, Outputs

CAMERA = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=160, height=90, fov_y_deg=40)


def one_line_error(capsys) -> str:
    lines = capsys.readouterr().err.splitlines()
    err = "\n".join(line for line in lines if line.strip() and "frame/s]" not in line)  # not tqdm's bar
    assert len(err.splitlines()) == 1 and "Traceback" not in err and ".tmp" not in err and STAGING_PREFIX not in err
    return err.strip()


def left_in(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_a_missing_output_folder_is_reported_before_the_scene_is_read(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["render", "missing.ply", "--orbit", "0,0", "-o", "nodir/a.png"]) == 1
    assert one_line_error(capsys) == "sketchrodgs render: error: -o nodir/a.png: the folder 'nodir' does not exist"
    assert left_in(tmp_path) == []


def test_extract_with_a_bad_overlay_path_leaves_no_rod(tmp_path, capsys):
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": [[10, 10], [100, 50]]}))
    args = ["extract", "sample:ring", "--camera", str(tmp_path / "cam.json"), "--stroke", str(tmp_path / "stroke.json")]
    assert main([*args, "-o", str(tmp_path / "r.json"), "--overlay", str(tmp_path / "nodir" / "o.png")]) == 1
    assert "--overlay" in one_line_error(capsys)
    assert left_in(tmp_path) == ["cam.json", "stroke.json"]


def test_extensions_are_refused_before_any_work(tmp_path, capsys):
    for command in (
        ["animate", "missing.ply", "r.json", "--grab", "1", "--to", "0,0,1", "--video", "x.avi", "-o", str(tmp_path)],
        ["render", "missing.ply", "-o", str(tmp_path / "a.bmp")],
        ["extract", "missing.ply", "--stroke", "s.json", "-o", str(tmp_path / "rod.txt")],
        ["camera", "missing.ply", "-o", str(tmp_path / "cam.json"), "--preview", str(tmp_path / "p.tiff")],
    ):
        with pytest.raises(SystemExit) as usage:
            main(command)
        assert usage.value.code == 2
        err = capsys.readouterr().err
        assert "expected" in err and "missing.ply" not in err
    assert left_in(tmp_path) == []


def test_jpg_outputs_are_jpeg(tmp_path):
    for name in ("view.jpg", "view.JPEG"):
        assert main(["render", "sample:ring", "--orbit", "0,30", "--width", "96", "-o", str(tmp_path / name)]) == 0
        assert (tmp_path / name).read_bytes()[:3] == b"\xff\xd8\xff"
    assert main(["render", "sample:ring", "--orbit", "0,30", "--width", "96", "-o", str(tmp_path / "v.png")]) == 0
    assert (tmp_path / "v.png").read_bytes()[:4] == b"\x89PNG"


def test_a_failed_extraction_leaves_nothing(tmp_path, capsys):
    CAMERA.save(tmp_path / "cam.json")
    (tmp_path / "stroke.json").write_text(json.dumps({"points": [[3, 3], [40, 4], [80, 3]]}))  # on background
    args = ["extract", "sample:ring", "--camera", str(tmp_path / "cam.json"), "--stroke", str(tmp_path / "stroke.json")]
    assert main([*args, "-o", str(tmp_path / "r.json")]) == 1
    one_line_error(capsys)
    assert left_in(tmp_path) == ["cam.json", "stroke.json"]


@pytest.fixture(scope="module")
def ring_rod(tmp_path_factory):
    from sketchrodgs import extract_rod, load_scene

    theta = np.radians(np.linspace(20, 160, 25))
    uv, _ = CAMERA.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    path = tmp_path_factory.mktemp("rod") / "rod.json"
    extract_rod(load_scene(data.sample("ring")), CAMERA, uv).save(path)
    return path


def animate(rod, out, *extra: str) -> list[str]:
    return ["animate", "sample:ring", str(rod), "--grab", "0.5", "--to", "0,0.05,0", "--hold", "0", "--fps", "10",
            "-o", str(out), *extra]  # fmt: skip


def test_a_failure_while_writing_leaves_no_output_folder_and_names_the_users_path(
    ring_rod, tmp_path, capsys, monkeypatch
):
    import sketchrodgs.video

    def disk_full(writer, frame):
        raise OSError(errno.ENOSPC, "No space left on device", str(writer.path))

    monkeypatch.setattr(sketchrodgs.video.VideoWriter, "append", disk_full)
    out = tmp_path / "anim"
    assert main(animate(ring_rod, out, "--duration", "0.2")) == 1
    assert one_line_error(capsys) == f"sketchrodgs animate: error: {out}: cannot write (No space left on device)"
    assert left_in(tmp_path) == []


def test_a_second_run_replaces_the_frames_of_the_first(ring_rod, tmp_path):
    out = tmp_path / "anim"
    assert main(animate(ring_rod, out, "--duration", "0.5", "--video", "none")) == 0
    (out / "notes.txt").write_text("mine")
    assert main(animate(ring_rod, out, "--duration", "0.2", "--video", "pull.gif")) == 0
    assert left_in(out / "frames") == ["frame_0001.png", "frame_0002.png"]  # not 5 frames, 2 of them stale
    assert left_in(out) == ["frames", "notes.txt", "pull.gif"] and left_in(tmp_path) == ["anim"]


def test_outputs_refuse_one_path_for_two_outputs(tmp_path):
    with pytest.raises(Exception, match="the same path is given for two outputs"), Outputs() as outputs:
        outputs.file(tmp_path / "a.png", "-o")
        outputs.file(tmp_path / "." / "a.png", "--overlay")
    assert left_in(tmp_path) == []


def test_folders_written_over_time_are_checked_first(tmp_path, capsys):
    """The demo's folder and the viewer's export folder: made if missing, but not in a missing folder."""
    (tmp_path / "file").write_text("mine")
    assert main(["view", "sample:ring", "-o", str(tmp_path / "nodir" / "exports"), "--port", "1"]) == 1
    assert f"the folder '{tmp_path / 'nodir'}' does not exist" in one_line_error(capsys)
    assert main(["demo", "-o", str(tmp_path / "file")]) == 1
    assert "exists and is not a folder" in one_line_error(capsys)
    assert left_in(tmp_path) == ["file"]
