from pathlib import Path

import yaml

from pipeline.common.mlflow_store import dvc_hash

ROOT = Path(__file__).resolve().parents[2]


def test_dvc_hash_is_the_lock_files_hash_of_a_stage_output_and_none_elsewhere(tmp_path):
    lock = yaml.safe_load((ROOT / "dvc.lock").read_text())["stages"]["generate_mazes"]["outs"]
    recorded = next(out["md5"] for out in lock if out["path"] == "data/mazes/test")
    assert dvc_hash(ROOT / "data/mazes/test") == recorded
    assert dvc_hash(ROOT / "pipeline") is None  # in the project, no stage's output
    assert dvc_hash(tmp_path) is None  # not in a DVC project
