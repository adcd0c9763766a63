"""PNG writing (`images.save_png`, encoded in Rust): exact pixels at every level, clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from sketchrodgs import data, load_scene, render
from sketchrodgs.errors import SketchRodGSError
from sketchrodgs.images import save_png, to_uint8


@pytest.mark.parametrize("level", [0, 1, 6, 9])
def test_png_holds_the_exact_pixels_at_every_level(tmp_path, level):
    rng = np.random.default_rng(level)
    noise = rng.integers(0, 256, size=(37, 53, 3), dtype=np.uint8)  # odd sizes, incompressible
    save_png(tmp_path / "noise.png", noise, compress_level=level)
    with Image.open(tmp_path / "noise.png") as read:
        assert read.mode == "RGB" and read.size == (53, 37)
        np.testing.assert_array_equal(np.asarray(read), noise)


def test_a_rendered_frame_reads_back_as_its_8_bit_colour(tmp_path):
    scene, camera = load_scene(data.sample("plant")), data.sample_camera("plant")
    rgb = render(scene, camera, background=(1, 1, 1)).rgb
    save_png(tmp_path / "frame.png", rgb, compress_level=1)  # float in [0, 1]: converted as to_uint8
    with Image.open(tmp_path / "frame.png") as read:
        np.testing.assert_array_equal(np.asarray(read), to_uint8(rgb))
    # the fast level stays small on a real frame: well under the raw 1.5 MB
    assert (tmp_path / "frame.png").stat().st_size < 400_000


def test_a_pil_image_is_written_as_rgb(tmp_path):
    image = Image.new("RGBA", (8, 4), (10, 20, 30, 40))
    save_png(tmp_path / "pil.png", image)
    with Image.open(tmp_path / "pil.png") as read:
        assert read.mode == "RGB"
        assert read.getpixel((3, 2)) == (10, 20, 30)


@pytest.mark.parametrize(
    ("image", "level", "says"),
    [
        (np.zeros((4, 4), np.uint8), 1, "image: expected shape"),
        (np.zeros((4, 4, 4), np.uint8), 1, "image: expected shape"),
        (np.zeros((0, 4, 3), np.uint8), 1, "image: height"),
        (np.zeros((4, 4, 3), np.uint8), 10, "compress_level"),
        (np.zeros((4, 4, 3), np.uint8), -1, "compress_level"),
        (np.zeros((4, 4, 3), np.uint8), 1.5, "compress_level"),
    ],
)
def test_bad_images_and_levels_are_refused_by_name_and_leave_no_file(tmp_path, image, level, says):
    with pytest.raises(SketchRodGSError, match=says):
        save_png(tmp_path / "bad.png", image, compress_level=level)
    assert not list(tmp_path.iterdir())
