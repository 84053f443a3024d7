"""The tests' memo of ``suggest_classes`` (tests/learned.py) returns what ``suggest_classes``
returns, and keys on the frames, the arguments and the code version."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests import learned
from vision.config import config_to_toml
from vision.suggest import suggest_classes
from vision.synthetic import particle_drum


@pytest.fixture
def scene_frames():
    return [particle_drum((200, 200), mix=0.3, slope_deg=30.0, seed=1, particle_r_frac=0.06).image]


def test_the_memo_gives_suggest_classes_result_and_learns_once(scene_frames, tmp_path, monkeypatch):
    monkeypatch.setattr(learned, "cache_dir", tmp_path)
    monkeypatch.setattr(learned, "_memory", {})
    want = config_to_toml(suggest_classes(scene_frames, per_frame=1500))
    before = dict(learned.calls)
    a = learned.learn(scene_frames, per_frame=1500)
    assert config_to_toml(a) == want
    assert learned.calls["learned"] == before["learned"] + 1
    monkeypatch.setattr(learned, "_memory", {})  # another worker: from the cache file
    b = learned.learn(scene_frames, per_frame=1500)
    assert config_to_toml(b) == want and b is not a
    assert learned.calls["learned"] == before["learned"] + 1 and learned.calls["reused"] == before["reused"] + 1
    # a stream is handed on as a stream (n_frames sets the samples per frame), read once
    seen = []

    def stream():
        for f in scene_frames:
            seen.append(1)
            yield f

    s = learned.learn(stream(), per_frame=1500, n_frames=1)
    assert len(seen) == 1 and config_to_toml(s) == want  # (a new key: learned again)
    assert learned.calls["learned"] == before["learned"] + 2


def test_the_key_changes_with_frames_arguments_and_code(scene_frames, tmp_path, monkeypatch):
    k = learned._key(scene_frames, "frames", {"k": 2})
    assert learned._key(scene_frames, "frames", {"k": 3}) != k
    assert learned._key(scene_frames, "stream", {"k": 2}) != k
    other = [f.copy() for f in scene_frames]
    other[0][100, 100, 0] ^= 1  # one bit of one pixel
    assert learned._key(other, "frames", {"k": 2}) != k
    v = learned.code_version()
    monkeypatch.setenv("MUTANT_UNDER_TEST", "vision.suggest.x_suggest_classes__mutmut_1")
    assert learned.code_version() != v
    monkeypatch.delenv("MUTANT_UNDER_TEST")
    copy = tmp_path / "repo"
    shutil.copytree(learned.REPO / "vision", copy / "vision")
    monkeypatch.setattr(learned, "REPO", copy)
    assert learned.code_version() == v
    p = Path(copy / "vision" / "suggest.py")
    p.write_text(p.read_text() + "\n# a change\n")
    assert learned.code_version() != v
