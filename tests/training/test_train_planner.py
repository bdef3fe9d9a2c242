"""Stage II training on a few real expert episodes, and the diffusion planners driving with the result."""

import dataclasses
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.observations import ObservationConfig, concatenate, episode_observations, save_observations
from pipeline.data.shards import shard_path
from pipeline.models.modeling_diffusion import load_policy, read_policy_export
from pipeline.planners import make_planner
from pipeline.planners.extensions.tour_vote import TourVote
from pipeline.planners.wrapper import innermost, layer
from pipeline.prediction.node_predictor import NodePredictor
from pipeline.training.policy import PlannerTrainConfig, split_episodes, train_planner
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode

TINY_MODEL = dict(
    max_nodes=96, max_neighbors=25, d_model=32, heads=2, encoder_layers=1, denoiser_layers=1, num_inference_steps=5
)
TINY_TRAIN = dict(
    max_epochs=2, batch_size=16, warmup_steps=2, val_accuracy_samples=24
)  # sampled accuracy spans 2 val batches


def wall_aware_inpaint(image: np.ndarray) -> np.ndarray:
    """A stand-in inpainter: every pixel not known occupied is free."""
    return (image != 0).astype(np.float32)


@pytest.fixture(scope="module")
def trained(expert_shard_dir, tmp_path_factory, mlflow_uri):
    root = tmp_path_factory.mktemp("planner")
    episodes = [e for k in range(2) for e in load_expert_episodes(shard_path(expert_shard_dir, k))]
    predictor = NodePredictor(wall_aware_inpaint)
    parts = [
        episode_observations(e, Protocol(), predictor, ObservationConfig(max_nodes=96), episode_id=i)
        for i, e in enumerate(episodes)
    ]
    paths = {}
    for variant in ("guide", "dare"):
        save_observations(root / f"{variant}.npz", concatenate(p[variant] for p in parts), {"variant": variant})
        paths[variant] = train_planner(
            root / f"{variant}.npz",
            root / variant,
            TINY_MODEL,
            TINY_TRAIN,
            tracking_uri=mlflow_uri,
            experiment_name="test_planner",
            run_name=variant,
        )
    return root, paths


def test_training_exports_an_ema_policy_with_its_history(trained):
    root, paths = trained
    export = read_policy_export(paths["guide"])
    assert export["epochs"] == 2 and len(export["history"]) == 2
    assert all(np.isfinite(h["val_loss"]) and 0 <= h["val_first_step_accuracy"] <= 1 for h in export["history"])
    assert export["samples"]["val"] > 0 and export["samples"]["train"] > 0
    # Where the weights were made travels with them (other CPU kernels train other weights).
    assert export["trained_on"]["torch"] == torch.__version__ and export["trained_on"]["device"] == "cpu"
    assert export["trained_on"]["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    policy, meta = load_policy(paths["guide"])
    assert policy.config.d_model == 32 and not policy.training
    assert (root / "guide" / "last.ckpt").is_file()


def test_resume_continues_from_the_last_checkpoint(trained, tmp_path, mlflow_uri):
    """Resuming restores the checkpoint's history and epoch count; it works in a copy so the shared export stays as made."""
    root, paths = trained
    out_dir = tmp_path / "guide"
    shutil.copytree(root / "guide", out_dir)
    first_history = read_policy_export(paths["guide"])["history"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = train_planner(
            root / "guide.npz",
            out_dir,
            TINY_MODEL,
            {**TINY_TRAIN, "max_epochs": 3},
            resume=True,
            tracking_uri=mlflow_uri,
            experiment_name="test_planner",
        )
    assert not [w for w in caught if "training from scratch" in str(w.message)]
    export = read_policy_export(path)
    assert export["epochs"] == 3 and [h["epoch"] for h in export["history"]] == [0, 1, 2]
    # Epochs 0-1 are the first run's records as the checkpoint stored them (wall-clock seconds included, which a
    # run from scratch could not reproduce); only epoch 2 was trained now.
    assert export["history"][:2] == first_history
    assert read_policy_export(paths["guide"])["history"] == first_history  # the shared export is untouched


def test_mismatched_model_and_observations_fail_clearly(trained):
    root, _ = trained
    with pytest.raises(ValueError, match="96 nodes"):
        train_planner(root / "guide.npz", root / "bad", {**TINY_MODEL, "max_nodes": 128}, TINY_TRAIN, mlflow=False)


def test_bad_settings_fail_before_checkpoints_files_or_mlflow_change(trained, tmp_path, mlflow_uri):
    """A fresh run with bad settings fails before its clean-up (the last run's checkpoints stay,
    byte for byte) and before an MLflow run is made; the error is a one-line ValueError."""
    import mlflow

    root, _ = trained
    out_dir = tmp_path / "guide"
    shutil.copytree(root / "guide", out_dir)
    before = {p.name: p.read_bytes() for p in sorted(out_dir.iterdir()) if p.is_file()}
    assert {"best.ckpt", "last.ckpt", "policy.pt"} <= set(before)
    failures = [
        ({"accelerator": "foo"}, r"accelerator 'foo': unknown; use one of auto, cpu, "),
        ({"devices": 0}, r"^devices: must be a number of devices >= 1, .*, got 0$"),
        ({"devices": "0"}, r"^devices: must be a number of devices >= 1, .*, got '0'$"),  # the CLI passes a string
        ({"devices": -1}, r"devices: must be a number of devices >= 1, .*got -1"),
    ]
    if not torch.cuda.is_available():  # Lightning's "No supported gpu backend found!" came after the clean-up
        failures.append(({"accelerator": "gpu"}, r"accelerator 'gpu': no GPU is visible to torch .*use cpu or auto"))
    for options, message in failures:
        with pytest.raises(ValueError, match=message):
            train_planner(
                root / "guide.npz",
                out_dir,
                TINY_MODEL,
                TINY_TRAIN,
                tracking_uri=mlflow_uri,
                experiment_name="test_planner_bad_settings",
                **options,
            )
        assert {p.name: p.read_bytes() for p in sorted(out_dir.iterdir()) if p.is_file()} == before, options
    assert mlflow.MlflowClient(tracking_uri=mlflow_uri).get_experiment_by_name("test_planner_bad_settings") is None
    with pytest.raises(ValueError, match="accelerator 'foo'"):
        train_planner(root / "guide.npz", tmp_path / "new", TINY_MODEL, TINY_TRAIN, accelerator="foo", mlflow=False)
    assert not (tmp_path / "new").exists()


def test_max_minutes_caps_the_wall_clock(trained, tmp_path):
    """A time cap (a timed GPU lease) stops a long run early and still exports a policy."""
    root, _ = trained
    path = train_planner(
        root / "dare.npz",
        tmp_path / "capped",
        TINY_MODEL,
        {**TINY_TRAIN, "max_epochs": 200, "max_minutes": 0.05},
        mlflow=False,
    )
    assert 1 <= read_policy_export(path)["epochs"] < 200
    assert load_policy(path)[0] is not None
    for bad in (0, -2, "soon", False):
        with pytest.raises(ValueError) as refused:
            PlannerTrainConfig.from_dict({"max_minutes": bad})
        assert str(refused.value) == (
            f"train.max_minutes: must be a finite number > 0 (minutes), or null (no cap), got {bad!r}"
        )
    for key, bad in (("max_epochs", 0), ("max_epochs", -1), ("max_epochs", 2.5), ("batch_size", 0)):
        with pytest.raises(ValueError) as refused:  # 0 epochs: an untrained export
            PlannerTrainConfig.from_dict({key: bad})
        assert str(refused.value) == f"train.{key}: must be a whole number >= 1, got {bad!r}"


def test_training_settings_round_trip_and_name_a_bad_key():
    config = PlannerTrainConfig.from_dict({"max_epochs": 3, "lr": 1, "max_minutes": 2})
    assert config.lr == 1.0 and config.max_minutes == 2.0  # numbers kept as floats: the same values as before
    assert PlannerTrainConfig.from_dict(dataclasses.asdict(config)) == config
    for values, message in (
        ({"val_fraction": 1.0}, "train.val_fraction: must be a number in [0, 1), got 1.0"),
        ({"augment": "yes"}, "train.augment: must be true or false, got 'yes'"),
        ({"max_epoch": 3}, "train.max_epoch: unknown setting (known: max_epochs, "),
    ):
        with pytest.raises(ValueError) as refused:
            PlannerTrainConfig.from_dict(values)
        assert str(refused.value).startswith(message), str(refused.value)


def test_episode_split_holds_out_whole_episodes():
    episode = np.repeat(np.arange(5), 10)
    train, val = split_episodes(episode, 0.4, seed=0)
    assert len(np.unique(episode[val])) == 2
    assert not set(episode[train]) & set(episode[val])
    assert len(train) + len(val) == 50


@pytest.mark.parametrize(
    "name, mode, candidates",
    [
        ("guide", "tour", 8),
        ("guide", "policy", 8),
        ("guide", "policy", 1),
        ("guide_noregion", "tour", 4),
        ("dare", "tour", 4),
        ("dare", "policy", 4),
    ],
)
def test_diffusion_planners_explore_a_maze_within_the_motion_rule(trained, generated_maze_dir, name, mode, candidates):
    _, paths = trained
    checkpoint = paths["dare" if name == "dare" else "guide"]
    options = {"candidates": candidates, "mode": mode}
    if name != "dare":
        options["inpaint"] = wall_aware_inpaint
    planner = make_planner(name, policy_file=str(checkpoint), num_inference_steps=3, **options)
    ground_truth = load_map(list_maps(generated_maze_dir)[0])
    result = run_episode(ground_truth, planner, Protocol())
    assert result.complete, (
        result.failure
    )  # tour targets / the stall guard guarantee progress even for a 2-epoch policy
    assert result.motion_violations == 0
    assert 0.0 <= planner.last_decision["fallback_share"] <= 1.0


def test_tour_mode_votes_follow_the_sampled_plans_and_moves_shorten_the_way_to_the_target(trained, generated_maze_dir):
    _, paths = trained
    planner = make_planner("guide", policy_file=str(paths["guide"]), num_inference_steps=3, inpaint=wall_aware_inpaint)
    ground_truth = load_map(list_maps(generated_maze_dir)[0])
    checked = []

    def check(episode) -> None:
        decision = planner.last_decision
        if not decision.get("sampled") or len(checked) >= 5:
            return
        graph = innermost(planner).graph
        position = np.asarray(episode.trajectory[-1])
        previous = graph.nearest_node(np.asarray(episode.trajectory[-2]))
        moved_to = graph.nearest_node(position)
        to_target, _ = graph.shortest_paths(decision["target"])
        step = float(np.hypot(*(graph.node_world[moved_to] - graph.node_world[previous])))
        assert to_target[moved_to] == pytest.approx(to_target[previous] - step)  # on a shortest known path
        assert decision["target"] == decision["tour"][0]
        assert np.all((decision["votes"] >= 0) & (decision["votes"] <= 1))
        checked.append(True)

    result = run_episode(ground_truth, planner, Protocol(), on_step=check)
    assert result.complete and len(checked) >= 3  # the first sampled decisions (a tiny maze may have fewer than 5)

    # Votes: a plan driven straight along the shortest path to an option votes 1 for it, a plan that stays votes 0.
    planner.reset(ground_truth, Protocol(), 0)
    episode = Episode(ground_truth, Protocol())
    observation = episode.observe()
    paper, vote = innermost(planner), layer(planner, TourVote)
    graph = paper.update_graph(observation)
    robot = paper.robot_node(observation)
    dist, pred = graph.shortest_paths(robot)
    useful = paper.reachable_useful(robot, dist)
    paper.update_global_graph(observation)
    paper.observe(observation.position)
    options = vote.tour.first_target_scores(paper.graph, paper.global_graph, robot, dist, useful)
    target = int(options["targets"][options["firsts"][0]])
    straight = graph.path_from_predecessors(pred, target)[:4]
    votes = vote.target_votes(robot, [straight, [robot]], options)
    assert votes[0] == pytest.approx(0.5)  # one plan of two heads straight at it, the other does not move
    unreachable = dict(options, option_distance=np.full_like(options["option_distance"], np.inf))
    assert np.all(vote.target_votes(robot, [straight], unreachable) == 0.0)  # no vote, no NaN


def test_tour_mode_with_no_prior_follows_the_guide_tsp_scores(trained, generated_maze_dir):
    _, paths = trained
    ground_truth = load_map(list_maps(generated_maze_dir)[0])
    planner = make_planner(
        "guide", policy_file=str(paths["guide"]), num_inference_steps=3, inpaint=wall_aware_inpaint, prior_weight=0.0
    )
    planner.reset(ground_truth, Protocol(), 0)
    observation = Episode(ground_truth, Protocol()).observe()
    planner.plan(observation)
    reference = make_planner("guide_tsp", inpaint=wall_aware_inpaint, global_graph=innermost(planner).global_config)
    reference.reset(ground_truth, Protocol(), 0)
    reference.plan(observation)
    assert planner.last_decision["target"] == reference.last_decision["tour"][0]


def test_diffusion_planner_options_are_checked(trained):
    _, paths = trained
    with pytest.raises(ValueError, match="action_steps"):
        make_planner("guide", policy_file=str(paths["guide"]), inpaint=wall_aware_inpaint, action_steps=20)
    with pytest.raises(FileNotFoundError, match=r"file not found \(expected a planner checkpoint\)"):
        make_planner("dare", policy_file="/nonexistent/policy.pt")
    with pytest.raises(ValueError, match="a guide policy .* dare needs a dare policy"):
        make_planner("dare", policy_file=str(paths["guide"]))
    with pytest.raises(ValueError, match="a dare policy .* guide needs a guide policy"):
        make_planner("guide", policy_file=str(paths["dare"]), inpaint=wall_aware_inpaint)
    with pytest.raises(ValueError, match="mode"):
        make_planner("guide", policy_file=str(paths["guide"]), inpaint=wall_aware_inpaint, mode="greedy")
    with pytest.raises(ValueError, match="prior_weight"):
        make_planner("guide", policy_file=str(paths["guide"]), inpaint=wall_aware_inpaint, prior_weight=-1.0)
    ddim = make_planner("guide", policy_file=str(paths["guide"]), inpaint=wall_aware_inpaint, sampler="ddim")
    assert type(innermost(ddim).policy.inference_scheduler).__name__ == "DDIMScheduler"


def test_without_pipeline_models_the_shipped_defaults_are_used(monkeypatch, tmp_path):
    import pipeline.models.defaults as guide_module

    for k in ("guide", "dare"):
        monkeypatch.setitem(
            guide_module.MODEL_FILES, f"policy_{k}", (tmp_path / f"{k}.pt", guide_module.MODEL_FILES[f"policy_{k}"][1])
        )
    planner = innermost(make_planner("dare"))
    assert planner.policy_source.endswith("planner_dare.pt") and "assets" in planner.policy_source
    for k in ("guide", "dare"):
        monkeypatch.setitem(
            guide_module.MODEL_FILES, f"policy_{k}", (tmp_path / f"{k}.pt", (tmp_path / f"shipped_{k}.pt",))
        )
    with pytest.raises(FileNotFoundError, match="train_planner"):
        make_planner("guide")


DDP_SCRIPT = """
import sys
from pipeline.training.policy import train_planner
path = train_planner(sys.argv[1], sys.argv[2], {model}, {train}, accelerator="cpu", devices=2, mlflow=False)
print(f"exported: {{path}}", flush=True)  # one write: two processes share the pipe
"""


@pytest.mark.slow
def test_two_process_training_exports_once(trained, tmp_path):
    """`--devices 2` (DDP, here two CPU processes as on two GPUs): the EMA copy is not a trainable
    weight DDP would refuse, validation is summed over both processes, and only rank zero exports."""
    import os
    import subprocess
    import sys

    root, _ = trained
    script = tmp_path / "ddp_train.py"
    script.write_text(DDP_SCRIPT.format(model=TINY_MODEL, train=TINY_TRAIN))
    out = tmp_path / "ddp"
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    done = subprocess.run(
        [sys.executable, str(script), str(root / "guide.npz"), str(out)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    lines = [line for line in done.stdout.splitlines() if line.startswith("exported:")]
    assert sorted(lines) == [f"exported: {out / 'policy.pt'}", "exported: None"]
    export = read_policy_export(out / "policy.pt")
    assert export["epochs"] == 2 and all(np.isfinite(h["val_loss"]) for h in export["history"])


@pytest.mark.slow
def test_a_training_in_a_child_process_starts_its_ddp_processes_there(trained, tmp_path):
    """`train_in_subprocess` (distil_policy's rounds on several devices): DDP reruns the child's
    script, not the caller's, and rank zero's export comes back."""
    from pipeline.training.policy_launch import train_in_subprocess

    root, _ = trained
    export = train_in_subprocess(
        observations=root / "guide.npz",
        out_dir=tmp_path / "child",
        model_config=TINY_MODEL,
        train_config=TINY_TRAIN,
        accelerator="cpu",
        devices=2,
        mlflow=False,
    )
    assert export == tmp_path / "child" / "policy.pt"
    assert read_policy_export(export)["epochs"] == 2


def test_a_failed_training_in_a_child_process_says_why(tmp_path):
    from pipeline.training.policy_launch import train_in_subprocess

    with pytest.raises(RuntimeError, match="(?s)policy training failed.*missing.npz: no observations"):
        train_in_subprocess(observations=tmp_path / "missing.npz", out_dir=tmp_path / "child", mlflow=False)


def test_a_resumed_run_trains_the_same_weights_as_an_uninterrupted_one(trained, tmp_path, monkeypatch):
    """The checkpoint carries the random generators (the loader's shuffle, torch's diffusion noise),
    so an interrupted and resumed run exports the uninterrupted run's EMA weights bit for bit."""
    from lightning.pytorch.callbacks import Callback

    import pipeline.training.lightning_run as lightning_run

    root, _ = trained
    settings = {**TINY_TRAIN, "max_epochs": 3}
    whole = train_planner(root / "guide.npz", tmp_path / "whole", TINY_MODEL, settings, mlflow=False)

    class Killed(Exception):
        pass

    class Interrupt(Callback):
        def on_train_epoch_start(self, trainer, module):
            if trainer.current_epoch == 2:
                raise Killed

    make_trainer = lightning_run.make_trainer
    monkeypatch.setattr(
        lightning_run, "make_trainer", lambda **o: make_trainer(**{**o, "callbacks": [*o["callbacks"], Interrupt()]})
    )
    with pytest.raises(Killed):
        train_planner(
            root / "guide.npz", tmp_path / "cut", TINY_MODEL, settings, mlflow=False, checkpoint_dir=tmp_path / "ckpt"
        )
    monkeypatch.setattr(lightning_run, "make_trainer", make_trainer)
    resumed = train_planner(
        root / "guide.npz",
        tmp_path / "cut",
        TINY_MODEL,
        settings,
        mlflow=False,
        resume=True,
        checkpoint_dir=tmp_path / "ckpt",
    )
    assert sorted(p.name for p in (tmp_path / "cut").iterdir()) == ["policy.pt"]
    a, b = torch.load(whole, weights_only=True), torch.load(resumed, weights_only=True)
    assert [row["epoch"] for row in b["history"]] == [0, 1, 2]
    assert all(torch.equal(a["state_dict"][k], b["state_dict"][k]) for k in a["state_dict"])


def test_a_fresh_run_can_start_from_an_export(trained, tmp_path, mlflow_uri):
    """DAgger fine-tunes each round from the round before: `init_policy` gives a fresh run its weights."""
    root, paths = trained
    no_steps = dict(TINY_TRAIN, max_epochs=1, lr=1e-12, warmup_steps=0, ema_decay=0.0)  # a step of ~0: weights kept
    export = train_planner(
        root / "guide.npz",
        tmp_path / "from",
        TINY_MODEL,
        no_steps,
        tracking_uri=mlflow_uri,
        experiment_name="test_planner",
        init_policy=paths["guide"],
    )
    start, _ = load_policy(paths["guide"])
    tuned, _ = load_policy(export)
    for name, value in start.state_dict().items():
        torch.testing.assert_close(tuned.state_dict()[name], value, atol=1e-6, rtol=0)
    scratch = train_planner(root / "guide.npz", tmp_path / "scratch", TINY_MODEL, dict(no_steps, seed=7), mlflow=False)
    drawn, _ = load_policy(scratch)
    assert any(
        not torch.allclose(drawn.state_dict()[k], v) for k, v in start.state_dict().items() if v.is_floating_point()
    )
    with pytest.raises(ValueError, match="model config differs"):
        train_planner(
            root / "guide.npz",
            tmp_path / "other",
            dict(TINY_MODEL, d_model=16, heads=2),
            no_steps,
            mlflow=False,
            init_policy=paths["guide"],
        )


TWO_NODE_SCRIPT = """
import sys
from pipeline.training.policy import train_planner
path = train_planner(sys.argv[1], sys.argv[2], {model}, {train}, accelerator="cpu", devices=1, num_nodes=2,
                     tracking_uri=sys.argv[3], experiment_name="two_nodes", run_name="two nodes",
                     checkpoint_dir=sys.argv[4], resume=sys.argv[5] == "resume")
print(f"exported: {{path}}", flush=True)  # one write: two processes share the pipe
"""


@pytest.mark.slow
def test_a_two_node_training_killed_after_an_epoch_resumes_into_one_mlflow_run(trained, tmp_path, mlflow_uri):
    """Two "nodes" on 127.0.0.1 (one process each, gloo), started as a cluster launcher starts
    them (MASTER_ADDR, MASTER_PORT, NODE_RANK): killed once the first epoch's checkpoint is written,
    started again with resume, they finish the epochs and leave one MLflow run."""
    import os
    import signal
    import socket
    import subprocess
    import sys
    import time

    import mlflow

    root, _ = trained
    script = tmp_path / "two_nodes.py"
    script.write_text(TWO_NODE_SCRIPT.format(model=TINY_MODEL, train={**TINY_TRAIN, "max_epochs": 3}))
    out, checkpoints = tmp_path / "out", tmp_path / "ckpt"

    def launch(mode: str) -> list[subprocess.Popen]:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        nodes = []
        for rank in (0, 1):
            env = {
                **os.environ,
                "PYTHONWARNINGS": "ignore",
                "MASTER_ADDR": "127.0.0.1",
                "MASTER_PORT": str(port),
                "NODE_RANK": str(rank),
                "LOCAL_RANK": "0",
                "WORLD_SIZE": "2",
            }
            logs = [open(tmp_path / f"{mode}_{rank}.{stream}", "w") for stream in ("out", "err")]  # files: a pipe fills
            nodes.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        str(script),
                        str(root / "guide.npz"),
                        str(out),
                        mlflow_uri,
                        str(checkpoints),
                        mode,
                    ],
                    cwd=tmp_path,
                    env=env,
                    stdout=logs[0],
                    stderr=logs[1],
                    text=True,
                    start_new_session=True,
                )
            )
            for log in logs:
                log.close()
        return nodes

    def logs(mode: str) -> str:
        return "".join(
            f"--- node {rank} ---\n" + (tmp_path / f"{mode}_{rank}.err").read_text()[-3000:] for rank in (0, 1)
        )

    def finish(nodes: list[subprocess.Popen], mode: str, seconds: float) -> None:
        """Wait for both nodes; one failing (the other then waits for it forever) or the time
        running out kills both and shows both nodes' logs."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline and any(node.poll() is None for node in nodes):
            if any(node.poll() not in (None, 0) for node in nodes):
                break
            time.sleep(0.5)
        failed = [node for node in nodes if node.poll() != 0]
        for node in failed:
            if node.poll() is None:
                os.killpg(node.pid, signal.SIGKILL)
                node.wait()
        assert not failed, f"{mode}: node(s) {[nodes.index(n) for n in failed]} failed or hung\n{logs(mode)}"

    first = launch("fresh")
    deadline = time.monotonic() + 240
    while (
        not (checkpoints / "last.ckpt").is_file()
        and time.monotonic() < deadline
        and all(node.poll() is None for node in first)
    ):
        time.sleep(0.2)
    for node in first:
        os.killpg(node.pid, signal.SIGKILL)
        node.wait()
    assert (checkpoints / "last.ckpt").is_file(), logs("fresh")
    assert not (out / "policy.pt").exists()
    second = launch("resume")
    finish(second, "resume", 300)
    outputs = [(tmp_path / f"resume_{rank}.out").read_text() for rank in (0, 1)]
    printed = sorted(line for stdout in outputs for line in stdout.splitlines() if line.startswith("exported:"))
    assert printed == [f"exported: {out / 'policy.pt'}", "exported: None"]  # only node 0 exports
    export = read_policy_export(out / "policy.pt")
    assert export["epochs"] == 3
    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    runs = client.search_runs([client.get_experiment_by_name("two_nodes").experiment_id])
    assert len(runs) == 1 and runs[0].info.status == "FINISHED"
    # Both parts logged into the one run, each of the 3 epochs at its own step. An epoch that ended after the
    # checkpoint the kill left is run again on resume and logged again at the same step (on a fast CPU, often).
    history = client.get_metric_history(runs[0].info.run_id, "val_loss")
    assert len({metric.step for metric in history}) == 3, [(metric.step, metric.value) for metric in history]
    assert runs[0].inputs.dataset_inputs and runs[0].inputs.dataset_inputs[0].dataset.name.endswith("guide.npz")


@pytest.mark.slow
def test_a_tracking_server_receives_the_benchmark_and_training_runs(trained, generated_maze_dir, tmp_path, monkeypatch):
    """`mlflow server` on 127.0.0.1 with its own artifact store: with MLFLOW_TRACKING_URI set, a
    tiny `guide benchmark` and a tiny training log there: runs, metrics, the model artifact, and
    the maze set / data set each run used as a dataset input."""
    import os
    import socket
    import subprocess
    import sys
    import time
    import urllib.request

    import mlflow

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    uri = f"http://127.0.0.1:{port}"
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "mlflow",
            "server",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--workers",
            "1",
            "--backend-store-uri",
            f"sqlite:///{tmp_path / 'server.db'}",
            "--artifacts-destination",
            str(tmp_path / "store"),
        ],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                urllib.request.urlopen(f"{uri}/health", timeout=1).close()
                break
            except OSError:
                assert server.poll() is None, server.stderr.read()[-3000:]
                time.sleep(0.5)
        env = {**os.environ, "MLFLOW_TRACKING_URI": uri, "MLFLOW_DISABLE_TELEMETRY": "true"}
        guide = str(Path(sys.executable).with_name("guide"))
        mazes = tmp_path / "mazes"
        mazes.mkdir()
        shutil.copy(sorted(generated_maze_dir.glob("*.png"))[0], mazes)
        bench = subprocess.run(
            [
                guide,
                "benchmark",
                "--maps",
                str(mazes),
                "--planner",
                "nearest_frontier",
                "--out",
                str(tmp_path / "bench"),
                "--workers",
                "1",
            ],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
        )
        assert bench.returncode == 0, bench.stderr[-3000:]
        monkeypatch.setenv("MLFLOW_TRACKING_URI", uri)
        root, _ = trained
        train_planner(
            root / "guide.npz",
            tmp_path / "policy",
            TINY_MODEL,
            TINY_TRAIN,
            experiment_name="on_server",
            run_name="tiny",
        )
        client = mlflow.MlflowClient(tracking_uri=uri)
        (bench_run,) = client.search_runs([client.get_experiment_by_name("benchmark").experiment_id])
        assert (
            bench_run.data.params["planner"] == "nearest_frontier" and bench_run.data.metrics["completion_rate"] == 1.0
        )
        (maze_input,) = bench_run.inputs.dataset_inputs
        assert maze_input.dataset.source_type == "local" and str(mazes) in maze_input.dataset.source
        assert "summary.md" in {a.path for a in client.list_artifacts(bench_run.info.run_id)}
        (train_run,) = client.search_runs([client.get_experiment_by_name("on_server").experiment_id])
        assert "val_loss" in train_run.data.metrics and "train_seconds" in train_run.data.metrics
        assert "policy.pt" in {a.path for a in client.list_artifacts(train_run.info.run_id)}
        assert train_run.inputs.dataset_inputs[0].dataset.name.endswith("guide.npz")
        assert any((tmp_path / "store").rglob("policy.pt"))  # uploaded through the server to its artifact store
    finally:
        server.terminate()
        server.wait(timeout=30)
