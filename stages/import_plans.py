"""DVC stage: the real floor plans of `plans.source` as a map family in data/plans/ (`guide plans import`).

Run as `python -m stages.import_plans` from the repository root. Reads only the `plans` section
of params.yaml: the source (data/real_plans/kth/, the 14 KTH plans under MapEx's Clear BSD
licence, by default; `dvc exp run -S plans.source=DIR` for a building's own plans or a robot's
saved maps), its resolution, the cell size and robot radius they are brought to, and the starts
drawn per plan. data/plans/ holds each plan as a ROS map with its start, manifest.json and the
sources' licence files (pipeline/world/plans.py says how).
"""

from __future__ import annotations

from pipeline.common.config import Section, positive, text, whole
from pipeline.common.paths import DATA
from pipeline.stage_runner import read_stage, run_stage_main, stage_arguments
from pipeline.world.plans import ImportReport, find_plan_sources, import_plans

OUT_DIR = DATA.plans


class Settings(Section):
    """The `plans` section of params.yaml."""

    source: text()
    resolution: positive("metres per pixel")
    cell_size: positive("metres")
    robot_radius_m: positive("metres")
    starts: whole(1)
    seed: whole(0)


def import_plan_folder(plans: Settings) -> ImportReport:
    """The `plans` settings' source read and written to data/plans/."""
    sources = find_plan_sources(plans.source, plans.resolution)
    return import_plans(sources, OUT_DIR, plans.cell_size, plans.robot_radius_m, plans.starts, plans.seed)


def main(params_path: str = "params.yaml") -> None:
    """Write data/plans/: the plans as ROS maps, manifest.json and the licence files."""
    report = import_plan_folder(read_stage(params_path, "plans", Settings))
    for dropped, equals in report.duplicates:
        print(f"dropped {dropped}: the same plan as {equals} (up to rotation and flip)")
    print(
        f"plans: {len(report.plans)} in {OUT_DIR} ({sum(p.free_m2 for p in report.plans):,.0f} m^2 free), "
        f"licence files: {', '.join(report.licences) or 'none'}"
    )


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
