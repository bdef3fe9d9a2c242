"""Stage I training: loss masking, data split and augmentation, train / resume / export, the stage."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from import_graph import ROOT

from pipeline.data.shards import write_shard
from pipeline.models import InpainterConfig, InpainterModel
from pipeline.models.modeling_inpainter import load_inpainter, read_inpainter_export
from pipeline.training.inpainter import TrainConfig, read_init_checkpoint, train_inpainter
from pipeline.training.inpainter_data import (
    NodeImagePairDataset,
    SizeGroupedBatchSampler,
    dihedral,
    hide_box,
    maze_count,
    maze_ids,
    pair_count,
    split_pairs,
)
from pipeline.training.inpainter_losses import evaluate_inpainter, hole_counts, inpainting_loss, precision_recall_f1
from pipeline.training.run_setup import PREVIOUS_CHECKPOINTS
from pipeline.world.protocol import Protocol

TINY = {"ngf": 4, "n_blocks": 1}
FAST = {"batch_size": 8, "val_fraction": 0.25, "lr": 0.005, "split": "rollout"}  # fixed batch counts


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def synthetic_maze(rng: np.random.Generator, side: int) -> np.ndarray:
    """A lattice's ground truth: a few straight corridors."""
    truth = np.zeros((side, side), dtype=bool)
    for _ in range(3):
        k = int(rng.integers(1, side - 1))
        if rng.random() < 0.5:
            truth[k, :] = True
        else:
            truth[:, k] = True
    return truth


def synthetic_pair(rng: np.random.Generator, size: int, truth: np.ndarray | None = None):
    """(observed, target, valid): part of a maze observed, centre-padded to `size`."""
    side = size - 4
    truth = synthetic_maze(rng, side) if truth is None else truth
    observed = np.full((side, side), 128, dtype=np.uint8)
    r0, c0 = rng.integers(0, side // 2, size=2)
    window = (slice(r0, r0 + side // 2), slice(c0, c0 + side // 2))
    observed[window] = np.where(truth[window], 255, 0)
    obs = np.full((size, size), 128, np.uint8)
    tgt = np.zeros((size, size), np.uint8)
    valid = np.zeros((size, size), bool)
    obs[2:-2, 2:-2], tgt[2:-2, 2:-2], valid[2:-2, 2:-2] = observed, np.where(truth, 255, 0), True
    return obs, tgt, valid


def write_pairs(
    directory: Path, shards: int = 2, per_size: int = 6, sizes=(32, 40), seed: int = 0, mazes: int = 0
) -> Path:
    """A Stage I data set as collect_pairs writes it: shards + manifest. With `mazes` > 0 the
    pairs of each size come from that many mazes (several views of each), else one maze each."""
    directory.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    pool = {size: [synthetic_maze(rng, size - 4) for _ in range(mazes)] for size in sizes}
    entries = []
    for k in range(shards):
        arrays = {"fingerprint": np.array("test")}
        for size in sizes:
            pairs = [
                synthetic_pair(rng, size, pool[size][int(rng.integers(mazes))] if mazes else None)
                for _ in range(per_size)
            ]
            for name, index in (("observed", 0), ("target", 1), ("valid", 2)):
                arrays[f"{name}_{size}"] = np.stack([p[index] for p in pairs])
        name = f"shard_{k:05d}.npz"
        write_shard(directory / name, arrays)
        entries.append({"file": name, "pairs": per_size * len(sizes)})
    (directory / "manifest.json").write_text(json.dumps({"shards": entries, "totals": {}}))
    return directory


@pytest.fixture(scope="module")
def pairs_dir(tmp_path_factory) -> Path:
    return write_pairs(tmp_path_factory.mktemp("pairs") / "pairs")


# --------------------------------------------------------------------------- loss and metrics
def test_loss_ignores_invalid_pixels():
    rng = np.random.default_rng(0)
    obs, tgt, valid = (torch.from_numpy(np.stack(a)) for a in zip(*[synthetic_pair(rng, 32) for _ in range(3)]))
    logits = torch.randn(3, 32, 32)
    loss, _ = inpainting_loss(logits, obs, tgt, valid)
    # Anything on the padding: extreme logits, flipped targets, even "known" observations.
    logits2, tgt2, obs2 = logits.clone(), tgt.clone(), obs.clone()
    logits2[~valid] = 1e4
    tgt2[~valid] = 255 - tgt2[~valid]
    obs2[~valid] = 255
    loss2, _ = inpainting_loss(logits2, obs2, tgt2, valid)
    assert torch.allclose(loss, loss2)
    # ... while a change on a valid hole pixel does count.
    hole = (obs == 128) & valid
    logits3 = logits.clone()
    logits3[hole] += 3.0
    assert not torch.allclose(loss, inpainting_loss(logits3, obs, tgt, valid)[0])


def test_loss_weights_hole_and_known():
    rng = np.random.default_rng(1)
    obs, tgt, valid = (torch.from_numpy(a)[None] for a in synthetic_pair(rng, 32))
    logits = torch.randn(1, 32, 32)
    known = (obs != 128) & valid
    changed = logits.clone()
    changed[known] = -changed[known]
    same_hole = inpainting_loss(logits, obs, tgt, valid, known_weight=0.0)[0]
    assert torch.allclose(same_hole, inpainting_loss(changed, obs, tgt, valid, known_weight=0.0)[0])
    _, parts = inpainting_loss(logits, obs, tgt, valid, known_weight=0.5)
    total, _ = inpainting_loss(logits, obs, tgt, valid, known_weight=0.5)
    assert torch.allclose(total, parts["hole"] + 0.5 * parts["known"])


def test_hole_metrics_count_only_the_hole():
    obs = torch.tensor([[128, 128, 128, 255]], dtype=torch.uint8)[None]
    tgt = torch.tensor([[255, 0, 255, 255]], dtype=torch.uint8)[None]
    valid = torch.tensor([[True, True, False, True]])[None]
    probs = torch.tensor([[0.9, 0.8, 0.9, 0.9]])[None]
    counts = hole_counts(probs, obs, tgt, valid, 0.5).tolist()
    assert counts == [1, 1, 0]  # pixel 2 is padding, pixel 3 is known
    assert precision_recall_f1(counts) == pytest.approx(
        {"precision": 0.5, "recall": 1.0, "f1": 2 / 3, "predicted": 2, "actual": 1}
    )


# --------------------------------------------------------------------------- data
def test_split_holds_out_whole_mazes(tmp_path):
    directory = write_pairs(tmp_path / "pairs", shards=3, per_size=10, mazes=4)
    train, val = split_pairs(directory, 0.25, "maze", seed=0)
    total = pair_count(train) + pair_count(val)
    assert total == 60 and 0.1 * total <= pair_count(val) <= 0.4 * total
    train_mazes = {m for g in train.values() for m in maze_ids(g)}
    val_mazes = {m for g in val.values() for m in maze_ids(g)}
    assert val_mazes and train_mazes and not train_mazes & val_mazes
    assert maze_count(train) + maze_count(val) == 8  # 4 mazes per size
    again = split_pairs(directory, 0.25, "maze", seed=0)[1]
    assert all(np.array_equal(again[s]["target"], val[s]["target"]) for s in val)


def test_single_maze_falls_back_to_the_rollout_split(tmp_path):
    directory = write_pairs(tmp_path / "pairs", shards=2, per_size=8, sizes=(32,), mazes=1)
    with pytest.warns(UserWarning, match="single maze"):
        train, val = split_pairs(directory, 0.25, "maze")
    assert pair_count(train) == 12 and pair_count(val) == 4


def test_rollout_split_keeps_the_tail_of_each_shard_and_size(pairs_dir):
    train, val = split_pairs(pairs_dir, 0.25, "rollout")
    assert set(train) == set(val) == {32, 40}
    assert all(len(train[s]["observed"]) == 2 * 4 and len(val[s]["observed"]) == 2 * 2 for s in (32, 40))
    from pipeline.data.pairs import load_pairs

    first = load_pairs([pairs_dir / "shard_00000.npz"])
    np.testing.assert_array_equal(val[32]["observed"][:2], first[32]["observed"][4:])


def test_hide_box_turns_observations_in_a_box_unknown_and_keeps_the_padding():
    torch.manual_seed(0)
    observed = np.full((32, 32), 255, np.uint8)
    valid = np.zeros((32, 32), bool)
    valid[4:28, 4:28] = True
    observed[~valid] = 0
    for _ in range(20):
        hidden = hide_box(observed, valid)
        assert (hidden[~valid] == 0).all()  # padding marks where the map ends
        changed = hidden != observed
        assert changed.any() and (hidden[changed] == 128).all() and valid[changed].all()
        rows, cols = np.nonzero(changed)
        assert changed[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1].all()  # one box
    assert (observed[valid] == 255).all()  # the input is not modified


def test_dihedral_augmentation_is_the_square_group():
    image = np.arange(16).reshape(4, 4)
    images = {dihedral(image, k).tobytes() for k in range(8)}
    assert len(images) == 8
    rng = np.random.default_rng(2)
    obs, tgt, valid = synthetic_pair(rng, 32)
    dataset = NodeImagePairDataset(
        {32: {"observed": obs[None], "target": tgt[None], "valid": valid[None]}}, augment=True
    )
    for _ in range(5):
        o, t, v = (x.numpy() for x in dataset[0])
        assert (o[~v] == 128).all() and ((o == 255) <= (t == 255)).all()  # pairs transformed together


def test_batches_hold_one_size():
    sizes = np.array([32] * 5 + [40] * 7 + [48] * 3)
    sampler = SizeGroupedBatchSampler(sizes, batch_size=4, shuffle=True, seed=0)
    batches = list(sampler)
    assert sorted(i for b in batches for i in b) == list(range(15))
    assert all(len({sizes[i] for i in b}) == 1 for b in batches)
    sampler.set_epoch(1)
    assert list(sampler) != batches or len(batches) == 1
    halves = [list(SizeGroupedBatchSampler(sizes, 4, True, 0, rank=r, world_size=2)) for r in (0, 1)]
    assert len(halves[0]) == len(halves[1]) and not {tuple(b) for b in halves[0]} & {tuple(b) for b in halves[1]}


# --------------------------------------------------------------------------- training
def test_train_export_and_resume(pairs_dir, tmp_path, mlflow_uri):
    out = tmp_path / "inpainter"
    artifacts = str(tmp_path / "mlartifacts")  # a new experiment's artifacts, kept out of ./mlruns
    path = train_inpainter(
        TINY,
        pairs_dir,
        out,
        max_epochs=1,
        tracking_uri=mlflow_uri,
        train_config=FAST,
        experiment_name="inpainter-test",
        artifact_location=artifacts,
    )
    assert path == out / "inpainter.pt" and path.is_file()
    assert (out / "last.ckpt").is_file() and (out / "best.ckpt").is_file()
    export = read_inpainter_export(path)
    assert export["epochs"] == 1 and [h["epoch"] for h in export["history"]] == [0]
    assert np.isfinite(export["history"][0]["train_loss"]) and 0 <= export["history"][0]["val_f1"] <= 1
    assert export["pairs"] == {"train": 16, "val": 8}
    model, config = load_inpainter(path)
    assert config == InpainterConfig(**TINY) and not model.training
    assert model.predict(np.full((32, 32), 128, np.uint8)).shape == (32, 32)
    assert export["num_parameters"] == model.num_parameters()
    assert export["trained_on"]["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    first_epoch = export["history"][0]
    # Resume: the epoch counter, step counter and history continue from last.ckpt (epoch 0 is
    # not trained again: its record, timing included, is the first run's).
    path = train_inpainter(
        TINY,
        pairs_dir,
        out,
        max_epochs=2,
        resume=True,
        tracking_uri=mlflow_uri,
        train_config=FAST,
        experiment_name="inpainter-test",
        artifact_location=artifacts,
    )
    export = read_inpainter_export(path)
    assert export["epochs"] == 2 and [h["epoch"] for h in export["history"]] == [0, 1]
    assert export["history"][0] == first_epoch
    ckpt = torch.load(out / "last.ckpt", map_location="cpu", weights_only=True)
    assert ckpt["epoch"] == 2 and ckpt["global_step"] == 4  # 2 batches (one per size) per epoch
    # The training checkpoint is also readable as a model.
    assert load_inpainter(out / "last.ckpt")[1] == config
    # The resumed training logged on into the first one's MLflow run, with the exported model as
    # an artifact; the setting it changed is a tag, since MLflow never changes a param.
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    (run,) = client.search_runs([client.get_experiment_by_name("inpainter-test").experiment_id])
    assert len(client.get_metric_history(run.info.run_id, "val_f1")) == 2  # an epoch from each part
    assert run.data.params["train_config/max_epochs"] == "1" and run.data.tags["resumed.train_config/max_epochs"] == "2"
    assert run.data.tags["trained_on.torch"] == torch.__version__
    assert any(p.name == "inpainter.pt" for p in (tmp_path / "mlartifacts").rglob("*"))


def test_training_reduces_the_loss(pairs_dir, tmp_path):
    path = train_inpainter(
        TINY,
        pairs_dir,
        tmp_path / "fit",
        max_epochs=4,
        mlflow=False,
        train_config={**FAST, "lr": 0.01, "augment": False, "split": "maze"},
    )
    export = read_inpainter_export(path)
    assert export["pairs"] == {"train": 18, "val": 6} and export["mazes"] == {"train": 18, "val": 6}
    history = export["history"]
    assert history[-1]["train_loss"] < history[0]["train_loss"]
    model, _ = load_inpainter(path)
    _, val = split_pairs(pairs_dir, 0.25)
    assert pair_count(val) == 6  # 24 pairs, each its own maze: a quarter held out
    metrics = evaluate_inpainter(model, val, (0.5,))[0.5]
    precision, recall, f1 = metrics["precision"], metrics["recall"], metrics["f1"]
    assert 0 <= precision <= 1 and 0 <= recall <= 1
    assert f1 == pytest.approx(2 * precision * recall / (precision + recall) if precision + recall else 0.0, abs=1e-6)
    everything_free = evaluate_inpainter(lambda images: torch.ones(images.shape, dtype=torch.float32), val, (0.5,))[0.5]
    assert everything_free["recall"] == pytest.approx(1.0)  # predicting every hole pixel free finds every free one


def test_adversarial_training_runs(pairs_dir, tmp_path):
    path = train_inpainter(
        TINY,
        pairs_dir,
        tmp_path / "gan",
        max_epochs=1,
        mlflow=False,
        train_config={**FAST, "adversarial_weight": 0.1, "discriminator_width": 8},
    )
    state = torch.load(tmp_path / "gan" / "last.ckpt", map_location="cpu", weights_only=True)["state_dict"]
    assert any(k.startswith("discriminator.") for k in state)
    assert not any(k.startswith("discriminator.") for k in read_inpainter_export(path)["state_dict"])


def test_fresh_run_clears_stale_checkpoints(pairs_dir, tmp_path):
    out = tmp_path / "stale"
    out.mkdir()
    (out / "best-v1.ckpt").write_text("old")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        train_inpainter(TINY, pairs_dir, out, max_epochs=1, mlflow=False, resume=True, train_config=FAST)
    assert not (out / "best-v1.ckpt").exists()


def file_bytes(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


def test_a_failed_run_keeps_the_previous_checkpoints(pairs_dir, tmp_path):
    """Bad settings, a missing or unreadable init checkpoint or missing data fail before the
    fresh run's clean-up: best.ckpt / last.ckpt / inpainter.pt stay as the last run left them."""
    out = tmp_path / "kept"
    train_inpainter(TINY, pairs_dir, out, max_epochs=1, mlflow=False, train_config=FAST)
    before = file_bytes(out)
    assert {"best.ckpt", "last.ckpt", "inpainter.pt"} <= set(before)
    corrupt = tmp_path / "corrupt.ckpt"
    corrupt.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    failures = [
        ({"accelerator": "foo"}, ValueError, r"accelerator 'foo': unknown; use one of auto, cpu, .*available here: "),
        ({"devices": 0}, ValueError, r"^devices: must be a number of devices >= 1, .*, got 0$"),
        ({"devices": -2}, ValueError, r"^devices: must be a number of devices >= 1, .*, got -2$"),
        ({"devices": "0"}, ValueError, r"^devices: must be a number of devices >= 1, .*, got '0'$"),
        ({"devices": -1}, ValueError, r"devices: must be a number of devices >= 1, .*got -1"),
        (
            {"init_checkpoint": tmp_path / "missing.ckpt"},
            FileNotFoundError,
            r"init checkpoint .*missing\.ckpt not found",
        ),
        (
            {"init_checkpoint": corrupt},
            ValueError,
            r"corrupt\.ckpt: not a readable checkpoint \(not a file written by torch\.save\)",
        ),
        ({"data_dir": tmp_path / "no-data"}, FileNotFoundError, r"no manifest"),
    ]
    if not torch.cuda.is_available():  # "No supported gpu backend found!" from Lightning, after the clean-up, before
        failures.append(
            (
                {"accelerator": "gpu"},
                ValueError,
                r"accelerator 'gpu': no GPU is visible to torch \(torch\.cuda\.is_available\(\) is False\); use cpu or auto",
            )
        )
    for options, error, message in failures:
        settings = {"data_dir": pairs_dir, **options}
        with warnings.catch_warnings(record=True) as caught, pytest.raises(error, match=message):
            warnings.simplefilter("always")
            train_inpainter(
                TINY, settings.pop("data_dir"), out, max_epochs=1, mlflow=False, train_config=FAST, **settings
            )
        assert not [str(w.message) for w in caught if "Big-LaMa" in str(w.message) or "unpickling" in str(w.message)], (
            options
        )
        assert file_bytes(out) == before, options


def test_a_run_that_crashes_in_fit_keeps_the_previous_checkpoints(pairs_dir, tmp_path, monkeypatch):
    import lightning as L

    out = tmp_path / "crash"
    train_inpainter(TINY, pairs_dir, out, max_epochs=1, mlflow=False, train_config=FAST)
    before = file_bytes(out)

    def crash(*args, **kwargs):
        raise RuntimeError("CUDA out of memory")

    monkeypatch.setattr(L.Trainer, "fit", crash)
    with pytest.raises(RuntimeError, match="out of memory"):
        train_inpainter(TINY, pairs_dir, out, max_epochs=1, mlflow=False, train_config=FAST)
    assert file_bytes(out) == before and not (out / PREVIOUS_CHECKPOINTS).exists()


def test_bad_settings_and_missing_data_fail_before_mlflow_and_files(pairs_dir, tmp_path, mlflow_uri):
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    out = tmp_path / "never"
    with pytest.raises(ValueError, match="accelerator 'foo'"):
        train_inpainter(
            TINY,
            pairs_dir,
            out,
            accelerator="foo",
            tracking_uri=mlflow_uri,
            experiment_name="inpainter-bad-settings",
            train_config=FAST,
        )
    with pytest.raises(FileNotFoundError, match="no manifest"):
        train_inpainter(
            TINY,
            tmp_path / "no-data",
            out,
            tracking_uri=mlflow_uri,
            experiment_name="inpainter-no-data",
            train_config=FAST,
        )
    assert client.get_experiment_by_name("inpainter-bad-settings") is None
    assert client.get_experiment_by_name("inpainter-no-data") is None
    assert not out.exists()


def test_init_checkpoint_reading(tmp_path):
    import argparse

    with pytest.raises(FileNotFoundError, match=r"init checkpoint .*nothing\.ckpt not found"):
        read_init_checkpoint(tmp_path / "nothing.ckpt")
    policy = ROOT / "pipeline" / "assets" / "planner_guide.pt"
    with pytest.raises(ValueError, match="planner_guide.pt: a planner policy export, not an inpainter export"):
        read_init_checkpoint(policy)  # named for what it is, not taken for Big-LaMa weights
    noise = tmp_path / "noise.ckpt"
    noise.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(
        ValueError, match=r"noise\.ckpt: not a readable checkpoint \(not a file written by torch\.save\)"
    ):
        read_init_checkpoint(noise)
    weights = {"state_dict": {"generator.model.1.weight": torch.ones(2, 2)}}
    plain = tmp_path / "plain.ckpt"
    torch.save(weights, plain)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # tensors only: no full unpickling
        assert torch.equal(read_init_checkpoint(plain)["state_dict"]["generator.model.1.weight"], torch.ones(2, 2))
    # A Lightning checkpoint holding config objects (as LaMa's do): unpickled fully, with a warning.
    lama = tmp_path / "lama.ckpt"
    torch.save({**weights, "hyper_parameters": argparse.Namespace(generator="ffc_resnet")}, lama)
    with pytest.warns(UserWarning, match="unpickling it fully"):
        payload = read_init_checkpoint(lama)
    assert payload["hyper_parameters"].generator == "ffc_resnet"
    # A damaged archive (cut short) and an archive holding something other than a dict: one-line errors.
    damaged = tmp_path / "damaged.ckpt"
    damaged.write_bytes(plain.read_bytes()[:-200])
    with pytest.raises(ValueError, match=r"damaged\.ckpt: not a readable checkpoint \("):
        read_init_checkpoint(damaged)
    listed = tmp_path / "list.ckpt"
    torch.save([torch.ones(1)], listed)
    with pytest.raises(ValueError, match=r"list\.ckpt: not a readable checkpoint \(it holds a list, not a dict\)"):
        read_init_checkpoint(listed)


def test_init_checkpoint_can_be_an_inpainter_export(pairs_dir, tmp_path):
    """Fine-tuning an export (the shipped default, say) starts from its weights, in its own layout."""
    first = train_inpainter(TINY, pairs_dir, tmp_path / "first", max_epochs=1, train_config=FAST, mlflow=False)
    start, start_config = load_inpainter(first)
    other = {"ngf": 8, "n_blocks": 1}  # the configured layout differs: the export's wins, with a warning
    tiny_steps = {**FAST, "lr": 1e-12}  # Adam moves each weight by about lr: the start stays visible
    with pytest.warns(
        UserWarning, match=r"init_checkpoint is an inpainter export: using its layout \(ngf 4, 1 blocks\)"
    ):
        tuned = train_inpainter(
            other,
            pairs_dir,
            tmp_path / "tuned",
            max_epochs=1,
            train_config=tiny_steps,
            mlflow=False,
            init_checkpoint=first,
        )
    model, config = load_inpainter(tuned)
    assert config == start_config == InpainterConfig(**TINY)
    for name, weight in start.named_parameters():
        assert torch.allclose(dict(model.named_parameters())[name], weight, atol=1e-9), name
    fresh = InpainterModel(InpainterConfig(**TINY))  # what a run without the init would start from
    assert not all(torch.allclose(dict(fresh.named_parameters())[n], w) for n, w in start.named_parameters())


def test_stage_writes_model_and_reports(pairs_dir, tmp_path, monkeypatch, mlflow_uri):
    from stages import train_inpainter as stage

    monkeypatch.chdir(tmp_path)
    Path("data").mkdir()
    Path("data/pairs").symlink_to(pairs_dir, target_is_directory=True)
    params = {
        "other_section": {"ignored": True},
        "protocol": {"node_resolution": 2.0},
        "train_inpainter": {"model": TINY, "max_epochs": 1, **FAST, "threshold": 0.4, "threads": 1},
    }
    Path("params.yaml").write_text(yaml.safe_dump(params))
    metrics = stage.main("params.yaml", tracking_uri=mlflow_uri, artifact_location=str(tmp_path / "mlartifacts"))
    assert sorted(p.name for p in Path("models/inpainter").iterdir()) == [
        "inpainter.pt"
    ]  # the output: the export alone
    for path in (
        "models/inpainter/inpainter.pt",
        "checkpoints/inpainter/last.ckpt",
        "reports/inpainter_metrics.json",
        "reports/inpainter_curves.png",
        "reports/inpainter_samples.png",
    ):
        assert Path(path).is_file(), path
    written = json.loads(Path("reports/inpainter_metrics.json").read_text())
    assert written == metrics
    assert written["threshold"] == 0.4 and "0.4" in written["by_threshold"]
    assert {
        "val_precision",
        "val_recall",
        "val_f1",
        "num_parameters",
        "train_seconds",
        "predict_ms_48",
        "val_mazes",
        "split",
    } <= set(written)
    # The protocol the pairs were drawn at travels with the model, for the planners' check.
    assert read_inpainter_export("models/inpainter/inpainter.pt")["protocol"] == Protocol(node_resolution=2.0).to_dict()
    # The metrics say where the model was trained, at the stage's thread count (params threads: 1).
    assert written["trained_on"]["threads"] == 1 and written["trained_on"]["torch"] == torch.__version__


DDP_SCRIPT = """
import sys
from pipeline.training.inpainter import train_inpainter
path = train_inpainter({model}, sys.argv[1], sys.argv[2], max_epochs=1, mlflow=False, train_config={train},
                       accelerator="cpu", devices=2)
print(f"exported: {{path}}", flush=True)  # one write: two processes share the pipe
"""


@pytest.mark.slow
@pytest.mark.parametrize("adversarial_weight", [0.0, 0.1])
def test_two_process_training_exports_once(pairs_dir, tmp_path, adversarial_weight):
    """`--devices 2` (DDP, two CPU processes standing in for two GPUs): each trains on its share
    of the batches, and only rank zero exports (the other process returns None). With the
    PatchGAN term each of its two steps leaves one network without gradients, which DDP
    accepts only when told to look for unused parameters."""
    import os
    import subprocess
    import sys

    script = tmp_path / "ddp_train.py"
    script.write_text(DDP_SCRIPT.format(model=TINY, train={**FAST, "adversarial_weight": adversarial_weight}))
    out = tmp_path / "ddp"
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    done = subprocess.run(
        [sys.executable, str(script), str(pairs_dir), str(out)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    lines = [line for line in done.stdout.splitlines() if line.startswith("exported:")]
    assert sorted(lines) == [f"exported: {out / 'inpainter.pt'}", "exported: None"]
    assert read_inpainter_export(out / "inpainter.pt")["epochs"] == 1


def test_max_minutes_caps_the_wall_clock(pairs_dir, tmp_path):
    """A time cap (a timed GPU lease) stops a long run early and still exports a model."""
    path = train_inpainter(
        TINY, pairs_dir, tmp_path / "capped", max_epochs=200, mlflow=False, train_config={**FAST, "max_minutes": 0.05}
    )
    export = read_inpainter_export(path)
    assert 1 <= export["epochs"] < 200
    assert load_inpainter(path)[0] is not None
    for bad in (0, -1.0, "ten", True):
        with pytest.raises(ValueError) as refused:
            TrainConfig.from_dict({"max_minutes": bad})
        assert str(refused.value) == (
            f"train_inpainter.max_minutes: must be a finite number > 0 (minutes), or null (no cap), got {bad!r}"
        )


def test_training_settings_round_trip_and_name_a_bad_key():
    import dataclasses

    config = TrainConfig.from_dict({"max_epochs": 3, "weight_decay": 0, "split": "rollout"})
    assert config.weight_decay == 0.0 and TrainConfig.from_dict(dataclasses.asdict(config)) == config
    for values, message in (
        ({"val_fraction": 0.0}, "train_inpainter.val_fraction: must be a number in (0, 1), got 0.0"),
        ({"split": "random"}, "train_inpainter.split: must be one of 'maze', 'rollout', got 'random'"),
        ({"threshold": 2}, "train_inpainter.threshold: must be a number in [0, 1] (P(free)), got 2"),
        ({"batch_size": 4.0}, "train_inpainter.batch_size: must be a whole number >= 1, got 4.0"),
    ):
        with pytest.raises(ValueError) as refused:
            TrainConfig.from_dict(values)
        assert str(refused.value) == message


def test_stage_killed_mid_training_resumes_from_its_last_epoch(pairs_dir, tmp_path):
    """SIGKILL once the first epoch's checkpoint is written, then the same command: it goes on from
    there (epochs add up), and other settings start afresh, saying so in one line."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from import_graph import ROOT

    (tmp_path / "data").mkdir()
    (tmp_path / "data/pairs").symlink_to(pairs_dir, target_is_directory=True)
    params = {"protocol": {}, "train_inpainter": {"model": TINY, "max_epochs": 3, **FAST, "threads": 1}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MLFLOW_TRACKING_URI": f"sqlite:///{tmp_path}/mlflow.db"}
    command = [sys.executable, "-m", "stages.train_inpainter"]
    last = tmp_path / "checkpoints/inpainter/last.ckpt"
    with subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) as run:
        deadline = time.monotonic() + 240
        while not last.is_file() and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert run.poll() is None, "training ended before it could be killed"
        os.kill(run.pid, signal.SIGKILL)
    assert not (tmp_path / "models/inpainter/inpainter.pt").exists()
    again = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-2000:]
    assert "train_inpainter: resuming from checkpoints/inpainter/last.ckpt after" in again.stdout
    metrics = json.loads((tmp_path / "reports/inpainter_metrics.json").read_text())
    assert metrics["epochs"] == 3 and 1 <= metrics["resumed_after_epochs"] < 3
    assert [row["epoch"] for row in read_inpainter_export(tmp_path / "models/inpainter/inpainter.pt")["history"]] == [
        0,
        1,
        2,
    ]
    params["train_inpainter"]["lr"] = 0.004
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    afresh = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert afresh.returncode == 0, afresh.stderr[-2000:]
    assert "was made with other settings or data: training afresh" in afresh.stdout
    assert json.loads((tmp_path / "reports/inpainter_metrics.json").read_text())["resumed_after_epochs"] is None


def test_a_resumed_run_trains_the_same_weights_as_an_uninterrupted_one(pairs_dir, tmp_path, monkeypatch):
    """The checkpoint carries the random generators' states (augmentation draws from torch's), so an
    interrupted and resumed run gives the uninterrupted run's weights bit for bit."""
    from lightning.pytorch.callbacks import Callback

    import pipeline.training.lightning_run as lightning_run

    whole = train_inpainter(TINY, pairs_dir, tmp_path / "whole", max_epochs=3, mlflow=False, train_config=FAST)

    class Killed(Exception):
        pass

    class Interrupt(Callback):
        def on_train_epoch_start(self, trainer, module):
            if trainer.current_epoch == 2:
                raise Killed  # after the second epoch's checkpoint

    make_trainer = lightning_run.make_trainer
    monkeypatch.setattr(
        lightning_run, "make_trainer", lambda **o: make_trainer(**{**o, "callbacks": [*o["callbacks"], Interrupt()]})
    )
    with pytest.raises(Killed):
        train_inpainter(TINY, pairs_dir, tmp_path / "cut", max_epochs=3, mlflow=False, train_config=FAST)
    assert not (tmp_path / "cut" / "inpainter.pt").exists()
    monkeypatch.setattr(lightning_run, "make_trainer", make_trainer)
    resumed = train_inpainter(
        TINY, pairs_dir, tmp_path / "cut", max_epochs=3, mlflow=False, train_config=FAST, resume=True
    )
    a, b = read_inpainter_export(whole), read_inpainter_export(resumed)
    assert [row["epoch"] for row in b["history"]] == [0, 1, 2]
    assert all(torch.equal(a["state_dict"][k], b["state_dict"][k]) for k in a["state_dict"])
