"""DVC stage: the headline metrics that `dvc exp show` compares, in reports/metrics.json.

Reads no section of params.yaml (it takes --params as every stage does, and needs none). Reads
reports/report.json (the report stage), reports/predictor/precision.csv (the eval_predictor stage)
and the summaries of the timed stages (reports/*.json); writes reports/metrics.json, the
pipeline's one DVC metrics file (pipeline/reporting/headline.py).
"""

from __future__ import annotations

from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.summarise import write_headline


def main() -> None:
    write_headline()


if __name__ == "__main__":
    stage_arguments(__doc__).parse_args()
    run_stage_main(main)
