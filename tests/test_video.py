"""Video files: frames stream into an MP4 one at a time; the file appears only when complete."""

from __future__ import annotations

import imageio.v2 as imageio
import numpy as np
import pytest

from sketchrodgs.errors import SketchRodGSError
from sketchrodgs.video import VideoWriter, write_video


def frames(count: int, height: int = 33, width: int = 48) -> list[np.ndarray]:
    """Frames with a bar moving right, odd height (padded for H.264)."""
    out = []
    for k in range(count):
        frame = np.zeros((height, width, 3), np.uint8)
        frame[:, 4 * k : 4 * k + 4] = 255
        out.append(frame)
    return out


@pytest.mark.parametrize("name", ["clip.mp4", "clip.gif"])
def test_frames_appended_one_by_one_make_the_whole_video(tmp_path, name):
    with VideoWriter(tmp_path / name, fps=10) as writer:
        for frame in frames(8):
            writer.append(frame)
    read = imageio.mimread(tmp_path / name)
    assert len(read) == 8
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no partial file beside it
    # the bar is where it was drawn (lossy MP4: its brightest column)
    assert abs(int(np.asarray(read[5])[..., :3].mean(axis=(0, 2)).argmax()) - 21) <= 2


def test_a_failure_mid_way_leaves_nothing_and_no_frames_is_an_error(tmp_path):
    with pytest.raises(RuntimeError, match="stop"), VideoWriter(tmp_path / "clip.mp4", fps=10) as writer:
        for frame in frames(3):
            writer.append(frame)
        raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SketchRodGSError, match="no frames to write"):
        write_video(tmp_path / "clip.mp4", [], fps=10)
    with pytest.raises(SketchRodGSError, match="cannot write '.avi' videos"):
        VideoWriter(tmp_path / "clip.avi", fps=10)
    assert list(tmp_path.iterdir()) == []
