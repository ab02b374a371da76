"""lfmdr_gym.atomic.atomic_file_set: the files of one output are all replaced, or none."""

import os

import pytest

from lfmdr_gym import atomic
from lfmdr_gym.atomic import atomic_file_set


def _listing(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_all_files_written_and_no_temporaries_left(tmp_path):
    out = tmp_path / "out" / "deeper"
    with atomic_file_set(out) as files:
        files.write_text("a.csv", "x\n1\n")
        files.write_bytes("b.bin", b"\x00\x01")
        files.path("c.json").write_text("{}")
        assert not (out / "a.csv").exists()  # nothing is in place before the block ends
    assert _listing(out) == {"a.csv": b"x\n1\n", "b.bin": b"\x00\x01", "c.json": b"{}"}


def test_temporary_keeps_the_suffix(tmp_path):
    with atomic_file_set(tmp_path) as files:
        assert files.path("map.png").suffix == ".png"
        files.write_text("map.png", "not really a png")


def test_error_in_block_leaves_folder_exactly_as_it_was(tmp_path):
    (tmp_path / "a.csv").write_text("old a")
    (tmp_path / "keep.txt").write_text("unrelated")
    before = _listing(tmp_path)
    with pytest.raises(RuntimeError, match="boom"), atomic_file_set(tmp_path) as files:
        files.write_text("a.csv", "new a")
        files.write_text("b.csv", "new b")
        raise RuntimeError("boom")
    assert _listing(tmp_path) == before


def test_error_while_renaming_puts_the_old_files_back(tmp_path, monkeypatch):
    (tmp_path / "a.csv").write_text("old a")
    (tmp_path / "b.csv").write_text("old b")
    before = _listing(tmp_path)
    real_replace = os.replace
    calls = []

    def failing_replace(src, dst):
        calls.append(dst)
        if len(calls) == 3:  # the third file of the set fails to be renamed
            raise OSError("disk gone")
        return real_replace(src, dst)

    with pytest.raises(OSError, match="disk gone"), atomic_file_set(tmp_path) as files:
        files.write_text("a.csv", "new a")
        files.write_text("new.csv", "new file")
        files.write_text("b.csv", "new b")
        monkeypatch.setattr(atomic.os, "replace", failing_replace)
    monkeypatch.setattr(atomic.os, "replace", real_replace)
    assert _listing(tmp_path) == before


def test_folder_created_by_a_failed_set_is_removed(tmp_path):
    out = tmp_path / "new" / "out"
    with pytest.raises(RuntimeError), atomic_file_set(out) as files:
        files.write_text("a.csv", "x")
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_file_names_must_be_plain(tmp_path):
    with pytest.raises(ValueError, match="plain file name"), atomic_file_set(tmp_path) as files:
        files.path("../escape.txt")
    assert list(tmp_path.iterdir()) == []
