"""The frame store is atomic: whole frames or nothing, orphans swept."""

from __future__ import annotations

import pytest

from service.store.frame_files import FrameStore

pytestmark = pytest.mark.timeout(60)


def test_the_frame_store_publishes_whole_frames_and_sweeps_orphans(tmp_path):
    store = FrameStore(tmp_path)
    a = "a" * 32
    store.save_files(a, {"frame.json": b"{}", "frame.npz": b"x"})
    assert sorted(p.name for p in (tmp_path / a).iterdir()) == ["frame.json", "frame.npz"]
    with pytest.raises(ValueError, match="unexpected frame file"):
        store.save_files("b" * 32, {"../evil": b""})
    (tmp_path / f".partial-{'c' * 32}").mkdir()  # a crash in the middle of a write
    (tmp_path / ("d" * 32)).mkdir()  # written, never committed
    assert sorted(store.sweep({a})) == sorted([f".partial-{'c' * 32}", "d" * 32])
    assert [p.name for p in tmp_path.iterdir()] == [a]
    with pytest.raises(KeyError):
        store.path("../../etc")
