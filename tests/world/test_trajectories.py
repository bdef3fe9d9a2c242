"""Tests of the trajectory file reader (pipeline/trajectories.py): what `guide replay` reads.

Every file is written into tmp_path by the test itself.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.protocol import Protocol
from pipeline.world.simulator import replay
from pipeline.world.trajectories import MAX_COORDINATE_M, read_trajectory_csv, write_trajectory_csv


def refused(path, *fragments: str) -> str:
    with pytest.raises(ValueError) as info:
        read_trajectory_csv(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message
    for fragment in fragments:
        assert fragment in message, message
    return message


def test_round_trip_is_unchanged(tmp_path):
    points = [(0.0, 0.0), (4.0, 0.0), (4.0, -8.0), (0.5, 1e6)]
    path = write_trajectory_csv(tmp_path / "run.csv", points)
    np.testing.assert_array_equal(read_trajectory_csv(path), np.array(points))


@pytest.mark.parametrize("value", ["1e308", "-1e308", "1e999", "inf", "-Infinity", "nan", "NaN", "1e10"])
def test_non_finite_or_huge_waypoints_are_a_malformed_file(tmp_path, value):
    path = tmp_path / "bad.csv"
    path.write_text(f"x,y\n0,0\n4,0\n{value},0\n")
    refused(path, "line 4", value)
    path.write_text(f"x,y\n0,0\n4,{value}\n")
    refused(path, "line 3", value)


def test_a_huge_waypoint_no_longer_reaches_the_simulator(tmp_path, small_maze):
    """1e308 used to escape as an OverflowError from the replay's lattice arithmetic."""
    path = tmp_path / "huge.csv"
    path.write_text("x,y\n0,0\n1e308,0\n")
    refused(path, "line 3", f"{MAX_COORDINATE_M:,.0f} m")
    with pytest.raises(OverflowError):  # what the reader now keeps out
        replay(small_maze, [(0.0, 0.0), (1e308, 0.0)], Protocol())


def test_a_coordinate_at_the_limit_is_still_read(tmp_path):
    path = tmp_path / "far.csv"
    path.write_text(f"x,y\n0,0\n{MAX_COORDINATE_M},{-MAX_COORDINATE_M}\n")
    assert read_trajectory_csv(path)[1].tolist() == [MAX_COORDINATE_M, -MAX_COORDINATE_M]


def test_a_file_that_is_not_utf8_names_the_file(tmp_path):
    path = tmp_path / "latin.csv"
    path.write_bytes(b"x,y\n0,0\n4\xff,0\n")
    refused(path, "not a UTF-8 text file", "0xff")
    utf16 = tmp_path / "utf16.csv"
    utf16.write_bytes("x,y\n0,0\n".encode("utf-16"))
    refused(utf16, "not a UTF-8 text file")


def test_a_leading_byte_order_mark_is_accepted(tmp_path):
    plain = write_trajectory_csv(tmp_path / "plain.csv", [(0, 0), (4, 0), (4, 4)])
    excel = tmp_path / "excel.csv"
    excel.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes().replace(b"\n", b"\r\n"))
    np.testing.assert_array_equal(read_trajectory_csv(excel), read_trajectory_csv(plain))


def test_a_folder_is_not_a_trajectory(tmp_path):
    folder = tmp_path / "runs"
    folder.mkdir()
    message = refused(folder, "is a folder")
    assert "not found" not in message
    refused(tmp_path / "missing.csv", "file not found")


def test_the_first_row_must_be_the_start(tmp_path):
    path = tmp_path / "no_start.csv"
    path.write_text("x,y\n4,0\n8,0\n")
    refused(path, "line 2", "first row must be the start 0,0", "'4,0'")
    path.write_text("x,y\n0.0004,-0.0004\n4,0\n")  # within replay's lattice tolerance
    assert read_trajectory_csv(path).shape == (2, 2)


def test_a_nul_byte_or_giant_field_is_a_value_error(tmp_path):
    path = tmp_path / "nul.csv"
    path.write_bytes(b"x,y\n0,0\n4\x00,0\n")
    with pytest.raises(ValueError, match="nul.csv"):
        read_trajectory_csv(path)
    path.write_text("x,y\n0,0\n" + "1" * 200_000 + ",0\n")
    message = refused(path)
    assert len(message) < 400  # one line, not the field


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("", "header 'x,y'"),
        ("a,b\n0,0\n", "header 'x,y'"),
        ("x,y\n", "no waypoint rows"),
        ("x,y\n0,0\n1,2,3\n", "line 3 is not two numbers"),
        ("x,y\n0,0\nfour,0\n", "not two numbers"),
    ],
)
def test_other_malformed_files(tmp_path, text, fragment):
    path = tmp_path / "t.csv"
    path.write_text(text)
    refused(path, fragment)


def test_a_write_that_fails_halfway_leaves_the_previous_file(tmp_path):
    path = write_trajectory_csv(tmp_path / "maze.csv", [(0.0, 0.0), (1.5, 0.0)])
    before = path.read_bytes()
    with pytest.raises(ValueError):
        write_trajectory_csv(path, [(0.0, 0.0), (2.0, 0.0), ("not a number", 0.0)])
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["maze.csv"]
