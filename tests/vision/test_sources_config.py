from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.vision import helpers as H
from vision.config import config_to_toml, load_config, parse_config
from vision.errors import VisionError
from vision.sources import open_source, read_image, source_kind

GOOD = """
[meter]
bed = "color"
min_pixels = 10
roi = [320, 240, 200]

[[classes]]
name = "teal"
hsv = [[[80, 80, 50], [95, 255, 255]]]

[[classes]]
name = "white"
hsv = [[[0, 0, 160], [179, 50, 255]]]
display_bgr = [255, 255, 255]
"""


def test_config_roundtrip_and_meter():
    cfg = parse_config(GOOD)
    assert [c.name for c in cfg.classes] == ["teal", "white"]
    assert cfg.roi.r_px == 200 and cfg.min_pixels == 10
    again = parse_config(config_to_toml(cfg))
    assert again.classes == cfg.classes and again.roi == cfg.roi
    assert not cfg.opening and "opening" not in config_to_toml(cfg)
    opened = parse_config(GOOD.replace("min_pixels = 10", "min_pixels = 10\nopening = true"))
    assert opened.opening and opened.make_meter().opening and parse_config(config_to_toml(opened)).opening


@pytest.mark.parametrize(
    "text, match",
    [
        (GOOD.replace("bed =", "colour = 1\nbed ="), "unknown key"),
        (GOOD.replace('name = "teal"', 'name = "teal"\nhue = 3'), "unknown key"),
        (GOOD.replace("[[80, 80, 50], [95, 255, 255]]", "[[95, 80, 50], [80, 255, 255]]"), "inverted H"),
        (GOOD.replace("[[0, 0, 160], [179, 50, 255]]", "[[0, 0, 160], [179, 50, 100]]"), "inverted V"),
        (GOOD.replace('bed = "color"', 'bed = "glow"'), "bed"),
        (GOOD.replace("min_pixels = 10", "min_pixels = 'ten'"), "integer"),
        (GOOD.replace("min_pixels = 10", "opening = 1"), "opening must be true or false"),
        (GOOD.replace("min_pixels = 10", "erode = true"), "erode was replaced by opening"),
        ("[meter\n", "TOML"),
        ("[meter]\nbed='color'\n[[classes]]\nname='a'\nhsv=[[[0,0,0],[10,255,255]]]\n", "two"),
    ],
)
def test_bad_configs(text, match):
    with pytest.raises(VisionError, match=match):
        parse_config(text)


def test_load_missing_config(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_config(tmp_path / "nope.toml")
    assert load_config(None).classes[0].name == "red"


def test_folder_and_list_in_name_order(tmp_path):
    for name in ("b.png", "a.png", "c.jpg"):
        cv2.imwrite(str(tmp_path / name), H.half_disks(64, 48))
    (tmp_path / "notes.txt").write_text("x")
    frames = list(open_source(tmp_path, fps=10))
    assert [f.name for f in frames] == ["a.png", "b.png", "c.jpg"]
    assert [f.t_s for f in frames] == pytest.approx([0, 0.1, 0.2])
    frames = list(open_source([str(tmp_path / "c.jpg"), str(tmp_path / "a.png")]))
    assert [f.name for f in frames] == ["a.png", "c.jpg"]
    assert source_kind("0") == "camera" and source_kind("rtsp://x/y") == "url"


def test_corrupt_and_grayscale_images_are_frames_with_errors(tmp_path):
    (tmp_path / "1.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    cv2.imwrite(str(tmp_path / "2.png"), np.zeros((10, 10), np.uint8))
    f1, f2 = list(open_source(tmp_path))
    assert f1.error and "decode" in f1.error and f1.image.size == 0
    assert f2.error is None and f2.image.ndim == 2


def test_image_depths_alpha_and_exif_orientation(tmp_path):
    """16-bit is scaled, alpha dropped, and a JPEG's EXIF orientation applied (phones store
    the pixels turned and a tag saying how to show them; unapplied, the drum's empty top is
    at the side and the slope is 90 deg off)."""
    from PIL import Image

    img = H.half_disks(64, 48)
    cv2.imwrite(str(tmp_path / "deep.png"), img.astype(np.uint16) * 257)
    cv2.imwrite(str(tmp_path / "alpha.png"), np.dstack([img, np.zeros((48, 64), np.uint8)]))
    turned = Image.fromarray(np.ascontiguousarray(np.rot90(img[:, :, ::-1])))  # stored turned 90 deg left
    exif = turned.getexif()
    exif[0x0112] = 6  # orientation: turn 90 deg right to show
    turned.save(tmp_path / "phone.jpg", exif=exif.tobytes(), quality=95)
    for name in ("deep.png", "alpha.png", "phone.jpg"):
        out, err = read_image(tmp_path / name)
        assert err is None and out.dtype == np.uint8 and out.shape == (48, 64, 3), name
        assert np.abs(out.astype(int) - img).mean() < (10 if name.endswith(".jpg") else 3), name


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(FileNotFoundError):
        open_source(tmp_path / "missing.mp4")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"garbage" * 10)
    with pytest.raises(VisionError, match="cannot open video"):
        open_source(bad)  # fails on opening, before any frame is asked for


def test_video_file_frames_and_loop(tmp_path):
    p = tmp_path / "v.mp4"
    vw = cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"mp4v"), 20, (64, 48))
    for _ in range(5):
        vw.write(H.half_disks(64, 48))
    vw.release()
    frames = list(open_source(p))
    assert len(frames) == 5 and frames[1].t_s == pytest.approx(0.05)
    it = open_source(p, loop=True)
    looped = [next(it) for _ in range(12)]
    assert looped[-1].index == 11 and looped[-1].t_s == pytest.approx(11 / 20)


class FlakyCamera:
    """A camera that delivers 3 frames, drops, refuses 2 reopenings, then works again."""

    opens = 0

    def __init__(self, target):
        FlakyCamera.opens += 1
        self.n = 0
        self.ok = FlakyCamera.opens not in (2, 3)

    def isOpened(self):
        return self.ok

    def read(self):
        self.n += 1
        if FlakyCamera.opens == 1 and self.n > 3:
            return False, None
        return True, np.zeros((4, 4, 3), np.uint8)

    def release(self):
        pass


@pytest.mark.timeout(20)
def test_camera_reconnects_with_backoff():
    FlakyCamera.opens = 0
    sleeps = []
    it = open_source(0, capture_factory=FlakyCamera, sleep=sleeps.append, backoff_s=(0.5, 8.0))
    frames = [next(it) for _ in range(6)]
    assert [f.index for f in frames] == list(range(6))
    assert FlakyCamera.opens == 4
    assert sleeps == [0.5, 1.0, 2.0]


@pytest.mark.timeout(20)
def test_camera_gives_up_after_tries():
    class Dead(FlakyCamera):
        def __init__(self, target):
            Dead.opens += 1

        def isOpened(self):
            return Dead.opens == 1

        def read(self):
            return False, None

    Dead.opens = 0
    it = open_source("0", capture_factory=Dead, sleep=lambda s: None, reconnect_tries=3)
    with pytest.raises(ConnectionError, match="3 tries"):
        next(it)
    Dead.opens = 5
    with pytest.raises(ConnectionError, match="cannot open camera"):
        open_source(1, capture_factory=Dead, sleep=lambda s: None)


def test_shipped_configs_load():
    from vision.colours import DEFAULT_CLASSES

    repo = Path(__file__).resolve().parents[2]
    assert load_config(repo / "configs" / "example.toml").classes == DEFAULT_CLASSES
    cfg = load_config(repo / "configs" / "pmma-blue-white.toml")
    assert [c.name for c in cfg.classes] == ["blue", "white"]


LEARNED = """
[meter]
min_share = 0.01

[[classes]]
name = "teal"
max_distance = 4.5
lab_mean = [[80.0, -12.0, -4.0]]
lab_cov = [[40.0, 0.0, 0.0, 4.0, 0.0, 4.0]]
lab_weight = [0.2]

[[classes]]
name = "white"
lab_mean = [[85.0, 0.0, 0.0], [50.0, 0.0, 0.0]]
lab_cov = [[30.0, 0.0, 0.0, 2.0, 0.0, 2.0], [100.0, 0.0, 0.0, 2.0, 0.0, 2.0]]
lab_weight = [0.2, 0.1]

[[classes]]
name = "background"
reject = true
lab_mean = [[3.0, 0.0, 0.0]]
lab_cov = [[10.0, 0.0, 0.0, 2.0, 0.0, 2.0]]
"""


def test_learned_config_roundtrip_and_classification():
    from vision.colours import classify

    cfg = parse_config(LEARNED)
    assert [c.name for c in cfg.counted] == ["teal", "white"] and cfg.classes[2].reject
    assert parse_config(config_to_toml(cfg)).classes == cfg.classes
    # teal, white, shaded white, black background, far-away red: by the model, never by brightness
    swatch = np.array([[[215, 210, 180], [235, 235, 235], [120, 120, 120], [5, 5, 5], [0, 0, 220]]], np.uint8)
    assert classify(swatch, cfg.classes).tolist() == [[1, 2, 2, 0, 0]]
    m = cfg.make_meter(roi=H.roi_for())
    assert [c.name for c in m.classes] == ["teal", "white"] and m.min_share == 0.01


@pytest.mark.parametrize(
    "old, new, match",
    [
        ("lab_mean = [[80.0, -12.0, -4.0]]", "lab_mean = [[nan, -12.0, -4.0]]", "finite"),
        ("lab_mean = [[80.0, -12.0, -4.0]]", "lab_mean = [[80.0, -12.0]]", "lab_mean"),
        ("lab_cov = [[40.0, 0.0, 0.0, 4.0, 0.0, 4.0]]", "lab_cov = [[40.0, 0.0, 0.0, -4.0, 0.0, 4.0]]",
         "positive definite"),
        ("lab_weight = [0.2]\n", "lab_weight = [0.2, 0.3]\n", "one entry per component"),
        ("max_distance = 4.5", "max_distance = inf", "max_distance"),
        ("max_distance = 4.5", "max_distance = -1", "max_distance"),
        ("min_share = 0.01", "min_share = nan", "min_share"),
        ("min_share = 0.01", "min_share = 2", "min_share"),
        ("min_share = 0.01", "collapse_ratio = -0.5", "collapse_ratio"),
        ("min_share = 0.01", "history = 0", "history"),
        ('name = "teal"\n', 'name = "teal"\nhsv = [[[0, 0, 0], [10, 255, 255]]]\n', "not both"),
        ("reject = true", "reject = 3", "reject"),
    ],
)
def test_bad_learned_configs(old, new, match):
    assert old in LEARNED
    with pytest.raises(VisionError, match=match):
        parse_config(LEARNED.replace(old, new, 1))


@pytest.mark.parametrize(
    "old, new, match",
    [
        ("display_bgr = [255, 255, 255]", 'display_bgr = [999, -1, "x"]', "display_bgr"),
        ("[[0, 0, 160], [179, 50, 255]]", "[[0, 0, 160], [179, 50, inf]]", "HSV range"),
        ("[[0, 0, 160], [179, 50, 255]]", "[[0, 0, 160.5], [179, 50, 255]]", "HSV range"),
        ("roi = [320, 240, 200]", "roi = [320, nan, 200]", "roi"),
        ("roi = [320, 240, 200]", 'roi = [320, 240, 200]\nroi_kind = "rect"\nhalf_w_px = nan', "half_w_px"),
        ("roi = [320, 240, 200]", 'roi = [320, 240, 200]\nroi_kind = "rect"\nhalf_w_px = -3', "half_w_px"),
        ("roi = [320, 240, 200]", "roi = [320, 240, -5]", "radius"),
        ('name = "teal"\n', 'name = "teal"\nreject = true\n', "reject"),
    ],
)
def test_bad_hsv_configs_name_the_key(old, new, match):
    assert old in GOOD
    with pytest.raises(VisionError, match=match):
        parse_config(GOOD.replace(old, new, 1))


def test_overlapping_hsv_ranges_warn():
    overlapping = GOOD.replace("[[0, 0, 160], [179, 50, 255]]", "[[0, 0, 160], [179, 120, 255]]")
    cfg = parse_config(overlapping)
    assert len(cfg.warnings) == 1 and "overlap" in cfg.warnings[0] and "'teal' wins" in cfg.warnings[0]
    assert parse_config(GOOD).warnings == ()
