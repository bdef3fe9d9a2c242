"""The registered `guide`, `guide_noregion`, `dare`, `guide_tsp` and `mapex`: GUIDE's policy
(`pipeline.planners.guide`), its tour ablation and MapEx, with our additions around them
(`pipeline.planners.extensions`).

This module sits above both: the paper's planner knows nothing of the additions, and each
addition only of what it wraps. `mode=tour` (the default) is the tour vote around the paper's
policy; `mode=policy` is the paper's policy driving, with several ranked samples and the stall
hand-over around it (`candidates=1` and a large `stall_steps` leave the paper's own planner).
The sliver gate is a fitted model any lattice planner's target rule consults
(`pipeline.models.sliver_gate`), on by default here as for `guide_tsp`. Every predicting planner
here comes wrapped in the trust in its predictions (`extensions/prediction_trust.py`), unless
`trust=false`.
"""

from __future__ import annotations

from typing import Annotated

from pipeline.common.config import config_dataclass, flag, maybe, real, text, whole
from pipeline.planners.baselines.mapex import MapExConfig, MapExPlanner
from pipeline.planners.config import OptionInfo, PlannerConfig, option
from pipeline.planners.extensions.lookahead import LookaheadConfig
from pipeline.planners.extensions.prediction_trust import PredictionTrustOptions, with_trust
from pipeline.planners.extensions.ranked_plans import SampledPlansConfig, rank_plans
from pipeline.planners.extensions.stall_handover import StallHandover, StallHandoverConfig
from pipeline.planners.extensions.tour_vote import TourVote, TourVoteConfig
from pipeline.planners.guide.configuration_guide import DareConfig, GuideConfig, GuideNoRegionConfig
from pipeline.planners.guide.configuration_guide_tsp import SPREAD_NODES, GuideTspConfig, TourOptions
from pipeline.planners.guide.guide import GuidePlanner
from pipeline.planners.guide.guide_tsp import GuideTspPlanner
from pipeline.planners.registry import register_planner
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.planner import Planner

MODES = ("tour", "policy")


def tour_help(name: str) -> str:
    """The help of one of guide_tsp's tour options, for guide's own default of it."""
    return TourOptions.__dataclass_fields__[name].metadata["help"]


@config_dataclass
class TourVoteOptions(
    GuideConfig,
    TourOptions,
    SampledPlansConfig,
    StallHandoverConfig,
    TourVoteConfig,
    LookaheadConfig,
    PredictionTrustOptions,
):
    """Every option of GUIDE's policy (`GuideConfig`) and of each addition around it, the tour's at
    guide_tsp's defaults (its clusters): the team guide's options (`pipeline.planners.team`)."""

    composition = (
        "the tour vote (extensions/tour_vote.py) around GUIDE's policy (guide/guide.py); mode=policy: "
        "ranked plans and the stall hand-over (extensions/) around it"
    )
    renamed = {"checkpoint": "policy_file", "inpainter_checkpoint": "inpainter_file", "block_model": "block_model_file"}
    part = "the mode"

    mode: Annotated[str, text(MODES)] = option(
        "tour",
        "tour: the policy's samples vote on the global graph's frontier tour (ours); "
        "policy: the sampled plans are driven (the paper's)",
    )

    @classmethod
    def options(cls) -> list[OptionInfo]:
        """The paper's options first (`GuideConfig`), then the mode and each addition's."""
        paper = {info.name for info in GuideConfig.options()}
        every = super().options()
        return [i for i in every if i.name in paper] + [i for i in every if i.name not in paper]

    def check(self) -> None:
        if self.lookahead and self.mode != "tour":
            raise ValueError(
                f"lookahead is an option of mode tour; got lookahead={self.lookahead!r} in mode {self.mode}"
            )
        super().check()


@config_dataclass
class SingleNodeTargets(PlannerConfig):
    """guide's own defaults of the tour options (`TourOptions`' keys): the options the policy votes
    on are single useful nodes (spread 0, none dropped), scored by boosted utility per metre with no
    tour regret (beta 0). guide_tsp's clusters and regret, tuned for its tour on mazes, cost guide
    distance on building floors and gained nothing on mazes or office floors. With no regret the tour only adds its own first target to the options, so it is
    solved cheaply."""

    spread: Annotated[
        float | None, maybe(real(0.0, note="0 = each useful node its own target"), f"{SPREAD_NODES:g} node spacings")
    ] = option(
        0.0,
        "metres: a useful node this close to a cluster's seed joins it (0: each useful node its own target; "
        f"null: {SPREAD_NODES:g} node spacings, guide_tsp's clusters)",
    )
    min_weight: Annotated[float, real(0.0, note="0 = keep every cluster")] = option(0.0, tour_help("min_weight"))
    beta: Annotated[float, real(0.0)] = option(0.0, tour_help("beta"))
    exact_max: Annotated[int, whole(1, 14)] = option(2, tour_help("exact_max"))
    max_moves: Annotated[int, whole(0, note="0 = no 2-opt / Or-opt moves")] = option(0, tour_help("max_moves"))


@config_dataclass
class GuideOptions(SingleNodeTargets, TourVoteOptions):
    """Every option of the registered `guide`: the paper's (`GuideConfig`) and each addition's, its
    targets single useful nodes (`SingleNodeTargets`)."""


@config_dataclass
class GuideNoRegionOptions(GuideOptions, GuideNoRegionConfig):
    pass


@config_dataclass
class DareOptions(GuideOptions, DareConfig):
    sliver_gate: Annotated[bool, flag()] = option(
        False, "consider first only the targets the sliver gate calls big (off: DARE as published)"
    )


def build_guide(options: GuideOptions, inpaint: InpaintFn | None = None, policy=None) -> Planner:
    """The planner `options` describe: the tour vote (mode tour) or the ranked, stall-guarded
    policy (mode policy), around the paper's `GuidePlanner`."""
    ranker = rank_plans if options.mode == "policy" else None
    paper = GuidePlanner(options, inpaint, policy, candidates=options.candidates, plan_ranker=ranker)
    if options.mode == "tour":
        return with_trust(TourVote(paper, options, options, options, options.description), options)
    planner = StallHandover(paper, options.stall_steps)
    planner.description = (
        f"{options.description} [mode policy; {options.candidates} ranked samples, stall hand-over "
        f"after {options.stall_steps}; policy {paper.policy_source}; {paper.predictor_source}; "
        f"{paper.gate_source}; K={paper.num_inference_steps}]"
    )
    return with_trust(planner, options)


@config_dataclass
class GuideTspOptions(GuideTspConfig, PredictionTrustOptions):
    pass


@config_dataclass
class MapExOptions(MapExConfig, PredictionTrustOptions):
    pass


def build_guide_tsp(options: GuideTspOptions, inpaint: InpaintFn | None = None) -> Planner:
    """The global graph's frontier tour (guide/guide_tsp.py), trusting its predictions as far as they hold."""
    return with_trust(GuideTspPlanner(options, inpaint=inpaint), options)


def build_mapex(options: MapExOptions, inpaint: InpaintFn | None = None) -> Planner:
    """MapEx (baselines/mapex.py), trusting its predicted map as far as it holds."""
    return with_trust(MapExPlanner(options, inpaint=inpaint), options)


register_planner("guide", GuideOptions)(build_guide)
register_planner("guide_noregion", GuideNoRegionOptions)(build_guide)
register_planner("dare", DareOptions)(build_guide)
register_planner("guide_tsp", GuideTspOptions)(build_guide_tsp)
register_planner("mapex", MapExOptions)(build_mapex)
