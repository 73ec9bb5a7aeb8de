"""The one atomic writer: a file appears whole or not at all, and no temporary file is left behind."""

from __future__ import annotations

import pytest

from texsynth.synth.errors import StorageError
from texsynth.synth.io.atomic import atomic_write_bytes, atomic_write_json, atomic_writer


def test_written_in_pieces_and_restarted_the_file_is_the_last_attempt(tmp_path) -> None:
    target = tmp_path / "out.bin"
    target.write_bytes(b"old")
    with atomic_writer(target) as fh:
        fh.write(b"broken stre")
        assert target.read_bytes() == b"old"  # readers still see the old file
        fh.seek(0)
        fh.truncate()
        fh.write(b"new ")
        fh.write(b"content")
    assert target.read_bytes() == b"new content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


def test_an_error_in_the_block_keeps_the_old_file_and_leaves_no_part(tmp_path) -> None:
    target = tmp_path / "out.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="stream broke"), atomic_writer(target) as fh:
        fh.write(b"half")
        raise RuntimeError("stream broke")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


def test_bytes_and_json_go_through_it(tmp_path) -> None:
    atomic_write_bytes(tmp_path / "a.bin", b"\x00\x01")
    atomic_write_json(tmp_path / "a.json", {"k": 1})
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "a.json").read_text() == '{\n  "k": 1\n}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.bin", "a.json"]


def test_a_folder_that_does_not_exist_is_a_storage_error_naming_the_file(tmp_path) -> None:
    with pytest.raises(StorageError, match=r"out\.bin"):
        atomic_write_bytes(tmp_path / "missing" / "out.bin", b"x")
