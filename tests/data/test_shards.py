import importlib.util
import json

import numpy as np
import pytest

from pipeline.data.shards import MANIFEST, ShardJob, read_manifest, run_shards, shard_path, write_shard


def make_counting_shard(job: ShardJob) -> dict:
    rng = np.random.default_rng([job.params["seed"], job.index])
    values = rng.integers(0, 100, size=job.params["size"])
    write_shard(shard_path(job.out_dir, job.index), {"values": values, "summary_items": np.array(values.size)})
    return {"items": int(values.size)}


def test_manifest_counts_and_determinism(tmp_path):
    manifest = run_shards(make_counting_shard, 3, tmp_path / "a", {"seed": 1, "size": 5}, progress=False)
    assert manifest["totals"]["items"] == 15 and len(manifest["shards"]) == 3
    assert read_manifest(tmp_path / "a")["totals"] == manifest["totals"]
    run_shards(make_counting_shard, 3, tmp_path / "b", {"seed": 1, "size": 5}, workers=2, progress=False)
    for k in range(3):
        assert shard_path(tmp_path / "a", k).read_bytes() == shard_path(tmp_path / "b", k).read_bytes()
    assert (tmp_path / "a" / MANIFEST).read_bytes() == (tmp_path / "b" / MANIFEST).read_bytes()


def test_the_data_do_not_depend_on_the_code_that_made_them(tmp_path, monkeypatch):
    """Other code (a refactor) that makes the same data gives the same bytes: the code's fingerprint
    decides only what is resumed, and lives in the work folder."""
    import pipeline.data.shards as shards

    run_shards(make_counting_shard, 2, tmp_path / "a", {"seed": 1, "size": 5}, work_dir=tmp_path / "wa", progress=False)
    monkeypatch.setattr(shards, "source_digest", lambda sources=None: "other code")
    calls = []
    run_shards(
        lambda job: calls.append(job.index) or make_counting_shard(job),
        2,
        tmp_path / "a",
        {"seed": 1, "size": 5},
        work_dir=tmp_path / "wa",
        progress=False,
    )
    assert calls == [0, 1]  # made by other code: not resumed from
    run_shards(make_counting_shard, 2, tmp_path / "b", {"seed": 1, "size": 5}, work_dir=tmp_path / "wb", progress=False)
    for name in ("shard_00000.npz", "shard_00001.npz", MANIFEST):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["manifest.json", "shard_00000.npz", "shard_00001.npz"]


def test_inputs_decide_what_is_resumed_but_are_not_in_the_data(tmp_path):
    """A model a collection runs (its digest): other bytes remake the shards, and the manifest does not name it."""
    calls = []

    def counted(job):
        calls.append(job.index)
        return make_counting_shard(job)

    params = {"seed": 1, "size": 5}
    run_shards(counted, 2, tmp_path / "a", params, work_dir=tmp_path / "w", inputs={"model": "one"}, progress=False)
    run_shards(counted, 2, tmp_path / "a", params, work_dir=tmp_path / "w", inputs={"model": "one"}, progress=False)
    assert calls == [0, 1]  # the same inputs: kept
    first = (tmp_path / "a" / MANIFEST).read_bytes()
    run_shards(counted, 2, tmp_path / "a", params, work_dir=tmp_path / "w", inputs={"model": "two"}, progress=False)
    assert calls == [0, 1, 0, 1]  # another model: made again
    assert (tmp_path / "a" / MANIFEST).read_bytes() == first and b"model" not in first


def test_a_deleted_output_is_published_again_from_the_work_folder(tmp_path):
    """DVC deletes a stage's outputs before it reruns the stage: the finished shards survive in the work folder."""
    import shutil

    run_shards(
        make_counting_shard, 2, tmp_path / "out", {"seed": 1, "size": 5}, work_dir=tmp_path / "work", progress=False
    )
    written = {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()}
    shutil.rmtree(tmp_path / "out")
    again = run_shards(
        make_counting_shard, 2, tmp_path / "out", {"seed": 1, "size": 5}, work_dir=tmp_path / "work", progress=False
    )
    assert again["made_this_run"] == []
    assert {p.name: p.read_bytes() for p in (tmp_path / "out").iterdir()} == written


def test_resume_keeps_finished_shards_and_redoes_broken_ones(tmp_path):
    out, work = tmp_path / "data", tmp_path / "work"
    run_shards(make_counting_shard, 3, out, {"seed": 2, "size": 4}, work_dir=work, progress=False)
    good = shard_path(work, 0).stat().st_mtime_ns
    shard_path(work, 1).write_bytes(b"half a shard")  # a crash mid-write of an older version
    (work / ".shard_00002.npz.999.tmp").write_bytes(b"temp")
    shard_path(work, 2).unlink()
    calls = []

    def tracking(job):
        calls.append(job.index)
        return make_counting_shard(job)

    manifest = run_shards(tracking, 3, out, {"seed": 2, "size": 4}, work_dir=work, progress=False)
    assert sorted(calls) == [1, 2]
    assert shard_path(work, 0).stat().st_mtime_ns == good
    assert not list(work.glob(".*.tmp")) and not list(tmp_path.glob(".*"))
    assert manifest["totals"]["items"] == 12


def test_changed_params_or_fewer_shards_leave_no_stale_data(tmp_path):
    out = tmp_path / "data"
    run_shards(make_counting_shard, 4, out, {"seed": 3, "size": 4}, progress=False)
    calls = []
    run_shards(
        lambda job: calls.append(job.index) or make_counting_shard(job), 2, out, {"seed": 4, "size": 4}, progress=False
    )
    assert sorted(calls) == [0, 1]
    assert sorted(p.name for p in out.glob("shard_*.npz")) == ["shard_00000.npz", "shard_00001.npz"]


def test_unfinished_collection_has_no_manifest(tmp_path):
    def failing(job):
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        run_shards(failing, 2, tmp_path / "d", {"seed": 0}, progress=False)
    with pytest.raises(FileNotFoundError, match="did not finish"):
        read_manifest(tmp_path / "d")


def test_manifest_bytes_depend_only_on_the_data_and_provenance_is_returned(tmp_path):
    """A fresh run and a resumed one write the same manifest bytes (DVC hashes the folder); the run's
    code version and the shards it made come back to the caller instead."""
    params = {"seed": 1, "size": 2}
    fresh = run_shards(make_counting_shard, 2, tmp_path / "m", params, progress=False)
    written = (tmp_path / "m" / MANIFEST).read_bytes()
    assert {"params", "shards", "totals"} == set(json.loads(written))
    assert fresh["made_this_run"] == [0, 1] and isinstance(fresh["code_version"], str) and fresh["code_version"]
    shard_path(tmp_path / "m.work", 1).unlink()
    resumed = run_shards(make_counting_shard, 2, tmp_path / "m", params, progress=False)
    assert resumed["made_this_run"] == [1]
    assert (tmp_path / "m" / MANIFEST).read_bytes() == written


def test_shard_count_rounds_up_to_whole_shards_and_says_so(capsys):
    from pipeline.data.shards import shard_count_for

    assert shard_count_for(300, 100, "pairs") == 3 and capsys.readouterr().out == ""
    assert shard_count_for(250, 100, "pairs") == 3
    assert (
        capsys.readouterr().out
        == "note: 250 pairs is not a multiple of 100 per shard; collecting 3 shards = 300 pairs\n"
    )
    assert shard_count_for(1, 8, "episodes") == 1
    for requested, per_shard in ((0, 100), (10, 0), (-5, 2)):
        with pytest.raises(ValueError, match="must be at least 1"):
            shard_count_for(requested, per_shard, "pairs")


def test_a_backend_that_cannot_run_fails_before_any_shard_is_touched(tmp_path):
    out = tmp_path / "data"
    run_shards(make_counting_shard, 2, out, {"seed": 5, "size": 4}, progress=False)
    before = sorted(p.name for p in out.iterdir())
    with pytest.raises(ValueError, match="unknown backend 'dask'"):
        run_shards(make_counting_shard, 2, out, {"seed": 6, "size": 4}, backend="dask", progress=False)
    if importlib.util.find_spec("ray") is None:
        with pytest.raises(
            ValueError, match=r"backend 'ray' needs Ray, which is not installed: pip install -e '\.\[ray\]'"
        ):
            run_shards(make_counting_shard, 2, out, {"seed": 6, "size": 4}, backend="ray", progress=False)
    assert sorted(p.name for p in out.iterdir()) == before  # the manifest and the shards of the earlier run stay
