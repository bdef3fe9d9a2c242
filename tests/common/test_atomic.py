"""Atomic outputs: whole or nothing, and the leftovers of a killed writer cleaned."""

import json

import pytest

from pipeline.common.atomic import atomic_file, atomic_folder, atomic_write_json, atomic_write_text


def test_a_file_appears_only_when_complete(tmp_path):
    path = tmp_path / "out" / "figure.png"
    with atomic_file(path) as tmp:
        assert tmp.suffix == ".png" and tmp.parent == path.parent and tmp.name.startswith(".")
        tmp.write_bytes(b"abc")
        assert not path.exists()
    assert path.read_bytes() == b"abc"
    assert [p.name for p in path.parent.iterdir()] == ["figure.png"]


def test_a_failed_write_leaves_the_old_file(tmp_path):
    path = tmp_path / "metrics.json"
    atomic_write_json(path, {"a": 1})
    with pytest.raises(RuntimeError):
        with atomic_file(path) as tmp:
            tmp.write_text("{half")
            raise RuntimeError("killed")
    assert json.loads(path.read_text()) == {"a": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.json"]


def test_a_writer_that_wrote_nothing_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="made no file"):
        with atomic_file(tmp_path / "x.txt"):
            pass


def test_leftovers_of_a_killed_writer_are_removed(tmp_path):
    (tmp_path / ".summary.json.partial-999.json").write_text("{")
    (tmp_path / ".maps.partial-999").mkdir()
    atomic_write_text(tmp_path / "summary.json", "{}")
    with atomic_folder(tmp_path / "maps") as folder:
        (folder / "a.png").write_bytes(b"1")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps", "summary.json"]


def test_a_folder_is_replaced_as_a_whole(tmp_path):
    target = tmp_path / "maps"
    target.mkdir()
    (target / "old.png").write_bytes(b"0")
    with atomic_folder(target) as folder:
        (folder / "new.png").write_bytes(b"1")
        assert (target / "old.png").exists()
    assert [p.name for p in target.iterdir()] == ["new.png"]
    with pytest.raises(ValueError):
        with atomic_folder(target) as folder:
            (folder / "newer.png").write_bytes(b"2")
            raise ValueError("stopped")
    assert [p.name for p in target.iterdir()] == ["new.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["maps"]


def test_a_file_and_a_folder_of_the_same_stem_keep_their_own_temporaries(tmp_path):
    """reports/benchmark.json and reports/benchmark/ are written side by side."""
    with atomic_folder(tmp_path / "benchmark") as folder:
        (folder / "metrics.csv").write_text("a")
        atomic_write_json(tmp_path / "benchmark.json", {"a": 1})
        assert folder.is_dir()
    assert (tmp_path / "benchmark" / "metrics.csv").is_file() and (tmp_path / "benchmark.json").is_file()
