"""The options of the registered `guide`, `guide_noregion` and `dare` planners.

One config serves both ways of running the policy (`mode`): the paper's receding-horizon
policy (`policy`, `pipeline.planners.guide.guide`) and our tour vote (`tour`, the default,
`pipeline.planners.extensions.tour_vote`), with the block-model lookahead as an option of the
tour vote. The tour options are `guide_tsp`'s: the tour vote scores the same first targets.
`guide_noregion` (every prediction enters the graph) and `dare` (the observed graph only) are
the paper's ablation and baseline: the same planner with another variant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from pipeline.planners.config import option
from pipeline.planners.extensions.lookahead import check_lookahead_options
from pipeline.planners.guide.guide_tsp import TourOptions
from pipeline.planners.options import check_int, check_number

MODES = ("tour", "policy")
SAMPLERS = ("ddpm", "ddim")
LOOKAHEAD_TARGETS = ("greedy", "tour")
LOOKAHEAD_ROLLOUTS = ("full", "fast")


@dataclass(frozen=True)
class GuideConfig(TourOptions):
    description = "GUIDE: diffusion policy conditioned on the region-evaluated global graph (predicted nodes)"
    needs_policy = True
    objects = ("inpaint", "policy")  # an injected inpainter and an injected policy (tests, notebooks)
    variant: ClassVar[str] = "guide"  # which trained policy: one trained on guide's or on dare's observations
    predicts: ClassVar[bool] = True  # predicted nodes enter the global graph (Sec. IV-B)
    region_evaluation: ClassVar[bool] = True  # ... filtered by region score r(g); False: every prediction
    inpainter_option: ClassVar[str] = "inpainter_checkpoint"  # `checkpoint` names the policy

    # --- the diffusion policy (Sec. IV-C)
    checkpoint: str | None = option(None, "the policy export [default: models/planner_guide/policy.pt "
                                          "(models/planner_dare/ for dare), else the shipped one]")
    num_inference_steps: int | None = option(None, "K denoising steps per sample [default: the policy's own]")
    sampler: str | None = option(None, "ddpm or ddim [default: the policy's own]")
    action_steps: int | None = option(None, "T_a of the T_p sampled steps executed before sampling again "
                                            "[default: the policy's own]")
    candidates: int = option(8, "plans sampled per decision, in one batched pass (mode policy, 1: the paper's "
                                "single sample)")
    stall_steps: int = option(3, "mode policy: after this many moves that reveal nothing, one step toward the "
                                 "nearest useful node instead")
    mode: str = option("tour", "tour: the policy's samples vote on the global graph's frontier tour (ours); "
                               "policy: the sampled plans are driven (the paper's)")
    # --- the predictor (Algorithm 1); threshold, min_component and count_threshold are TourOptions'
    inpainter_checkpoint: str | None = option(None, "the inpainter export [default: models/inpainter/inpainter.pt, "
                                                    "else the shipped one]")
    # --- the tour vote (mode tour)
    prior_weight: float = option(1.0, "mode tour: an option's score is multiplied by 1 + prior_weight x the share "
                                      "of samples heading for it (0: the policy does not vote)")
    # --- the block-model lookahead (mode tour)
    lookahead: int = option(0, "mode tour: roll out this many candidate targets on maps drawn from the block model "
                               "and head for the shortest (0 = off)")
    lookahead_samples: int = option(4, "maps drawn per lookahead decision")
    lookahead_targets: str = option("greedy", "greedy: guide's choice and gated greedy's best targets are rolled "
                                              "out; tour: guide's best tour options")
    lookahead_commit: bool | None = option(None, "keep the lookahead's target until reached or no longer a target, "
                                                 "as the rollouts assumed [None: on]")
    lookahead_rollout: str | None = option(None, "full (gated greedy, a choice at every node) or fast (greedy "
                                                 "walking each target's whole path) [None: full]")
    lookahead_workers: int | None = option(None, "2: the rollouts shared with a forked second process, the same "
                                                 "routes [None: 1]")
    block_model: str | None = option(None, "the block model [default: models/block_model/block_model.pt, else the "
                                           "shipped one]")

    def check(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"mode must be tour or policy, got {self.mode!r}")
        check_int("lookahead", self.lookahead, 0, note="0 = off; the number of best tour options rolled out")
        if self.lookahead == 1 or (self.lookahead and self.mode != "tour"):
            raise ValueError(f"lookahead must be 0 (off) or at least 2, in mode tour; got {self.lookahead!r} in mode {self.mode}")
        check_lookahead_options(self.lookahead_samples, 20.0, 0.0, 1.0,
                                1 if self.lookahead_workers is None else self.lookahead_workers)
        if self.lookahead_targets not in LOOKAHEAD_TARGETS:
            raise ValueError(f"lookahead_targets must be greedy or tour, got {self.lookahead_targets!r}")
        if self.lookahead_rollout not in (None, *LOOKAHEAD_ROLLOUTS):
            raise ValueError(f"lookahead_rollout must be fast or full, got {self.lookahead_rollout!r}")
        lookahead_only = (self.block_model, self.lookahead_commit, self.lookahead_rollout, self.lookahead_workers)
        if any(value is not None for value in lookahead_only) and not self.lookahead:
            raise ValueError("block_model, lookahead_commit, lookahead_rollout or lookahead_workers is given but the "
                             "lookahead is off; add lookahead=3")
        check_number("prior_weight", self.prior_weight, 0.0, note="0 = the policy does not vote")
        check_int("stall_steps", self.stall_steps, 1)
        check_int("candidates", self.candidates, 1)
        if self.sampler is not None and self.sampler not in SAMPLERS:
            raise ValueError(f"sampler must be ddpm or ddim, got {self.sampler!r}")
        super().check()

    def model_slots(self) -> dict[str, str]:
        lookahead = {"block_model": "block_model"} if self.lookahead > 0 else {}
        return {**super().model_slots(), "checkpoint": f"policy_{self.variant}", **lookahead}


@dataclass(frozen=True)
class GuideNoRegionConfig(GuideConfig):
    description = "GUIDE w/o region evaluation: the guide policy on a graph with every predicted node"
    region_evaluation = False


@dataclass(frozen=True)
class DareConfig(GuideConfig):
    description = "DARE: diffusion policy on the observed graph only (no prediction, no region evaluation)"
    variant = "dare"
    predicts = False
    region_evaluation = False

    sliver_gate: bool = option(False, "consider first only the targets the sliver gate calls big (off: DARE as "
                                      "published)")
