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

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import (Fields, Flag, Maybe, Real, Satisfies, Text, Whole, check_stage, fraction, keys_of,
                                      positive)
from pipeline.planners.registry import make_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.distil_policy import distil_policy
from pipeline.world.protocol import Protocol


def check_teacher(teacher: dict) -> None:
    """A registered planner and options it accepts; the planner must report its target (run time says so)."""
    if not isinstance(teacher, dict) or set(teacher) - {"planner", "options"} or "planner" not in teacher:
        raise ValueError("a mapping {planner: NAME, options: {KEY: VALUE}}")
    options = teacher.get("options") or {}
    if not isinstance(options, dict):
        raise ValueError("options must be a mapping of planner options")
    make_config(str(teacher["planner"]), **options)


SETTINGS = Fields({
    "teacher": Satisfies(check_teacher, "a teacher planner with its options"),
    "start_policy": Maybe(Text(note="a guide policy export"), "models/planner_guide/policy.pt"),
    "inpainter": Maybe(Text(note="an inpainter export"), "models/inpainter/inpainter.pt"),
    "rounds": Whole(0, note="DAgger rounds after round 0"),
    "teacher_episodes": Whole(1),
    "episodes": Whole(1),
    "episodes_per_shard": Whole(1),
    "random_starts": Flag(),
    "seed": Whole(0),
    "train": Fields({
        "max_epochs": Whole(1), "batch_size": Whole(1), "lr": positive(), "weight_decay": Real(0.0),
        "warmup_steps": Whole(0), "ema_decay": fraction(), "val_fraction": Real(0.0, 1.0, high_open=True),
        "augment": Flag(), "seed": Whole(0), "max_minutes": Maybe(positive("minutes"), "no cap"),
        "val_accuracy_samples": Whole(1),
    }),
    "eval_mazes": Whole(2, note="paired comparison needs at least 2"),
    "eval_side_m": positive("metres"),
    "eval_seed": Whole(0),
    "workers": Whole(0, note="0 or 1: in this process"),
    "threads": Maybe(Whole(0, note="0: torch's default"), "torch's default"),
    "accelerator": Text(note="Lightning's accelerator: cpu, gpu, auto"),
    "experiment": Text(note="an MLflow experiment"),
})
KEYS = keys_of(SETTINGS)


def main(params_path: str = "params.yaml") -> dict:
    check_stage(params_path, "distil_policy", SETTINGS)
    params = load_params(params_path)
    section = complete_section(params, "distil_policy", params_path, KEYS)
    protocol = Protocol.from_dict(params.get("protocol") or {})
    return distil_policy(section, protocol)


if __name__ == "__main__":
    args = stage_arguments(__doc__).parse_args()
    run_stage_main(main, args.params)
