"""Stage II data (the `collect_expert` stage): expert episodes on the training mazes, stored as raw per-step
state; written as shards, with a summary and a picture of one episode.

The episodes run on DARE's lattice (`door_graph` off) at every scale. The expert's coverage model
plans lattice paths on the ground truth and steps along them one lattice node at a time (it
plans on the lattice under any protocol); its labels are lattice nodes, the nodes the policy
chooses among, and the episodes' done rule is the lattice's as well. The policy's observations
(`build_observations`) are built under the stage's own protocol.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Any, cast

from pydantic import ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, flag, satisfies, whole
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.data.collect import EXPERT_SOURCES, ExpertConfig, collect_expert_shard
from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.shards import rate_per_minute, run_shards, shard_count_for, shard_path
from pipeline.planners import planner_config
from pipeline.planners.registry import accepted_options, make_config
from pipeline.reporting.render import render_frame, save_png
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol

TRAIN_MAZES = DATA.mazes_train
OUT_DIR = DATA.expert
SUMMARY = REPORTS.expert
PREVIEW = REPORTS.expert_preview


class Settings(Section):
    """The `collect_expert` section of params.yaml."""

    seed: Annotated[int, whole(0)]
    episodes: Annotated[int, whole(1)]
    episodes_per_shard: Annotated[int, whole(1)]
    planner: Annotated[str, satisfies(planner_config, "a registered planner name", str)]
    planner_options: dict[str, Any]
    horizon: Annotated[int, whole(1, note="future waypoints per step")]
    random_starts: Annotated[bool, flag()]
    workers: Annotated[int, whole(0, note="0 or 1: in this process")]

    @field_validator("planner_options")
    @classmethod
    def _options_the_planner_takes(cls, options: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        """An option the planner does not take fails here, by its key, not in the first worker."""
        planner = info.data.get("planner")
        if planner is None:  # the planner itself was refused
            return options
        accepted = accepted_options(planner, options)
        for key in options:
            if key not in accepted:
                raise PydanticCustomError(
                    "unknown_key",
                    "{planner} has no option {key}",
                    {"key": key, "known": ", ".join(accepted), "planner": planner},
                )
        make_config(planner, **options)
        return options


def episode_preview(out_dir: Path, path: Path, cell_size: float) -> None:
    """The first stored episode: its final rebuilt belief and the expert's path."""
    episode = load_expert_episodes(shard_path(out_dir, 0))[0]
    belief = None
    for belief in episode.beliefs():
        pass
    ground_truth = GroundTruthMap(
        free=episode.ground_truth, start_cell=episode.start_cell, cell_size=cell_size, name=episode.map_name
    )
    trajectory = [cast(tuple[float, float], tuple(map(float, p))) for p in episode.positions]
    image = render_frame(
        ground_truth,
        belief.copy(),
        trajectory,
        title=f"expert episode on {episode.map_name}: {len(trajectory) - 1} steps",
    )
    save_png(image, path)


def collect_expert(settings: Settings, protocol: Protocol, backend: str | None = None):
    """The expert episode shards from the `collect_expert` settings, a summary and a preview; the summary."""
    maps = tuple(str(p) for p in generated_maps(TRAIN_MAZES, "training mazes"))
    shard_count = shard_count_for(settings.episodes, settings.episodes_per_shard, "episodes")
    config = ExpertConfig(
        maps=maps,
        episodes_per_shard=settings.episodes_per_shard,
        planner=settings.planner,
        planner_options=tuple(sorted(settings.planner_options.items())),
        horizon=settings.horizon,
        seed=settings.seed,
        protocol=replace(protocol, door_graph=False) if protocol.uses_door_graph else protocol,  # module doc
        random_starts=settings.random_starts,
    )
    started = time.perf_counter()
    manifest = run_shards(
        collect_expert_shard,
        shard_count,
        OUT_DIR,
        {"config": config},
        workers=settings.workers,
        backend=backend,
        description="expert shards",
        sources=EXPERT_SOURCES,
        work_dir=CHECKPOINTS.expert,
    )
    seconds = time.perf_counter() - started
    episode_preview(OUT_DIR, PREVIEW, protocol.cell_size)
    totals = manifest["totals"]
    summary = {
        "episodes": totals["episodes"],
        "complete": totals["complete"],
        "steps": totals["steps"],
        "bytes": totals["bytes"],
        "bytes_per_step": round(totals["bytes"] / max(1, totals["steps"]), 1),
        "seconds": round(seconds, 1),
        # Rate over the shards made by this run (a resumed run reuses finished shards).
        "episodes_per_minute": rate_per_minute(manifest, "episodes", seconds),
        "code_version": manifest["code_version"],  # provenance here, not in the data folder
    }
    atomic_write_json(SUMMARY, summary)
    print(
        f"{totals['episodes']} expert episodes ({totals['complete']} complete), {totals['steps']} steps, "
        f"{totals['bytes'] / max(1, totals['steps']):.0f} bytes per stored step -> {OUT_DIR}"
    )
    return manifest
