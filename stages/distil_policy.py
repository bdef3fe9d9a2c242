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

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.distil_policy import Settings, distil_policy


def main(params_path: str = "params.yaml") -> dict:
    return distil_policy(read_stage(params_path, "distil_policy", Settings), read_protocol(params_path))


if __name__ == "__main__":
    args = stage_arguments(__doc__).parse_args()
    run_stage_main(main, args.params)
