"""The registered names of the paper's planner: `guide`, its ablation `guide_noregion` and the
DARE baseline `dare`, each with its config (`configuration_guide`).

`mode=policy` builds the paper's receding-horizon policy (`GuidePlanner`); `mode=tour`, the
default, builds our tour vote on the same policy (`TourVotePlanner`).
"""

from __future__ import annotations

from pipeline.planners.extensions.tour_vote import TourVotePlanner
from pipeline.planners.guide.configuration_guide import DareConfig, GuideConfig, GuideNoRegionConfig
from pipeline.planners.guide.guide import GuidePlanner
from pipeline.planners.registry import register_planner
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.planner import Planner


def build(config: GuideConfig, inpaint: InpaintFn | None = None, policy=None) -> Planner:
    """The planner `config` describes: the tour vote (mode tour) or the paper's policy (mode policy)."""
    planner = TourVotePlanner if config.mode == "tour" else GuidePlanner
    return planner(config, inpaint=inpaint, policy=policy, name=config.name)


register_planner("guide", GuideConfig)(build)
register_planner("guide_noregion", GuideNoRegionConfig)(build)
register_planner("dare", DareConfig)(build)
