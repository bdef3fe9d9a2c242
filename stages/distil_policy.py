"""DVC stage: DAgger (ours): the guide policy distilled from a belief-only teacher, the policy driving.

Reads only the `distil_policy` section of params.yaml (and the shared `protocol`). Round 0: the
teacher drives and labels its own states; each later round: the policy of the round before drives
(`guide:mode=policy`), the teacher labels every state it reaches, the rounds' data is aggregated and
the policy fine-tuned. Writes each round's labelled episodes to data/dagger/round_<r>/, the last
round's policy to models/planner_distilled/policy.pt, and per round the agreement with the teacher
and the closed-loop distance on fresh mazes beside greedy_utility to reports/distil_metrics.json
and reports/distil_rounds.png. Unfinished work is kept in checkpoints/distil/.
"""

from __future__ import annotations

from typing import Any

from pydantic import field_validator

from pipeline.common.config import Section, every_key, flag, maybe, positive, text, whole
from pipeline.planners.registry import make_config
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.training.policy import PlannerTrainConfig
from pipeline.training.run_setup import DEVICES
from pipeline.workflows.distil_policy import distil_policy


class Teacher(Section):
    """The planner DAgger imitates: a registered planner and options it accepts (it must report its
    target: the run says so when it does not)."""

    planner: text(note="a registered planner name")
    options: dict[str, Any] = {}

    @field_validator("options")
    @classmethod
    def _options_the_planner_takes(cls, options: dict[str, Any], info: Any) -> dict[str, Any]:
        if info.data.get("planner") is not None:
            make_config(info.data["planner"], **options)
        return options


class Settings(Section):
    """The `distil_policy` section of params.yaml."""

    teacher: Teacher
    start_policy: maybe(text(note="a guide policy export"), "models/planner_guide/policy.pt")
    inpainter: maybe(text(note="an inpainter export"), "models/inpainter/inpainter.pt")
    rounds: whole(0, note="DAgger rounds after round 0")
    teacher_episodes: whole(1)
    episodes: whole(1)
    episodes_per_shard: whole(1)
    random_starts: flag()
    seed: whole(0)
    train: every_key(PlannerTrainConfig)
    eval_mazes: whole(2, note="paired comparison needs at least 2")
    eval_side_m: positive("metres")
    eval_seed: whole(0)
    workers: whole(0, note="0 or 1: in this process")
    threads: maybe(whole(0, note="0: torch's default"), "torch's default")
    accelerator: text(note="Lightning's accelerator: cpu, gpu, auto")
    devices: DEVICES = 1
    experiment: text(note="an MLflow experiment")


def main(params_path: str = "params.yaml") -> dict:
    return distil_policy(read_stage(params_path, "distil_policy", Settings), read_protocol(params_path))


if __name__ == "__main__":
    args = stage_arguments(__doc__).parse_args()
    run_stage_main(main, args.params)
