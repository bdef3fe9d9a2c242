"""The options of GUIDE's policy as the paper runs it (Sec. IV), and of its ablation and baseline.

`GuideConfig` holds the paper's options only: the policy and predictor files, the predictor's
taus, the global graph's region settings, the receding horizon (T_a of the policy's T_p, after
its T_o observations), K denoising steps, and the sampling seed. T_o and T_p are the trained
policy's own (its export records them). What we added beyond the paper (several ranked samples,
the stall hand-over, the tour vote, the lookahead, the sliver gate) has its own config in
`pipeline.planners.extensions`; the registered `guide` combines them (`pipeline.planners.catalog`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pipeline.common.config import config_dataclass, maybe, text, whole
from pipeline.planners.config import option
from pipeline.planners.predicting import GlobalGraphOptions

SAMPLERS = ("ddpm", "ddim")


@config_dataclass
class GuideConfig(GlobalGraphOptions):
    description = "GUIDE: diffusion policy conditioned on the region-evaluated global graph (predicted nodes)"
    part = "the diffusion policy (Sec. IV-C)"
    needs_policy = True
    objects = ("inpaint", "policy")  # an injected inpainter and an injected policy (tests, notebooks)
    renamed = {"checkpoint": "policy_file", "inpainter_checkpoint": "inpainter_file"}
    variant: ClassVar[str] = "guide"  # which trained policy: one trained on guide's or on dare's observations
    predicts: ClassVar[bool] = True  # predicted nodes enter the global graph (Sec. IV-B)
    region_evaluation: ClassVar[bool] = True  # ... filtered by region score r(g); False: every prediction

    # action_steps and num_inference_steps are bounded above by the policy (its T_p, its training
    # timesteps): `GuidePlanner` checks those bounds when it loads it.
    policy_file: Annotated[str | None, maybe(text())] = option(
        None,
        "the policy export [default: models/planner_guide/policy.pt "
        "(models/planner_dare/ for dare), else the shipped one]",
    )
    action_steps: Annotated[int | None, maybe(whole(1), "the policy's own")] = option(
        None, "T_a of the T_p sampled steps executed before sampling again [default: the policy's own]"
    )
    num_inference_steps: Annotated[int | None, maybe(whole(1), "the policy's own")] = option(
        None, "K denoising steps per sample [default: the policy's own]"
    )
    sampler: Annotated[str | None, maybe(text(SAMPLERS), "the policy's own")] = option(
        None, "ddpm or ddim [default: the policy's own]"
    )
    seed: Annotated[int | None, maybe(whole(0), "the episode's seed")] = option(
        None, "the sampling seed [default: the episode's seed]"
    )

    def model_slots(self) -> dict[str, str]:
        return {**super().model_slots(), "policy_file": f"policy_{self.variant}"}


@config_dataclass
class GuideNoRegionConfig(GuideConfig):
    description = "GUIDE w/o region evaluation: the guide policy on a graph with every predicted node"
    region_evaluation = False


@config_dataclass
class DareConfig(GuideConfig):
    description = "DARE: diffusion policy on the observed graph only (no prediction, no region evaluation)"
    variant = "dare"
    predicts = False
    region_evaluation = False
