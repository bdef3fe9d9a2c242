"""Each planner's option defaults per scale: one table per named protocol, declared here once.

A planner's config carries one set of defaults. Some options are shortest at one scale and
cost distance at another: the targets `guide`'s policy votes on are best as single useful nodes
on building floors (1 m lattice, 10 m sensor) and as `guide_tsp`'s clusters in the maze
benchmark (4 m lattice, 20 m sensor), for `guide` and `guide_noregion`; `dare`, whose policy sees
the observed graph only, is no shorter with the clusters there and keeps single nodes. A planner is made before any protocol is known; at each
reset `ProtocolMatchedModels` takes the options this table gives for the protocol it runs at,
except those the caller set. `guide planners --options NAME --protocol PROTOCOL` prints them.

A protocol takes the table of the named protocol (`pipeline.world.protocol.PROTOCOLS`) whose
model inputs it shares, else of the one whose lattice spacing is nearest (a ROS map's own cell
size changes nothing; a 2 m lattice and finer is the building scale, as for the door-aware graph).
"""

from __future__ import annotations

import math
from typing import Any

from pipeline.world.protocol import MODEL_INPUT_FIELDS, PROTOCOLS, Protocol

CLUSTERS: dict[str, Any] = {"spread": None, "min_weight": 30.0, "beta": 1.5, "exact_max": 9, "max_moves": 200}
"""guide_tsp's clusters (its tour options' defaults) as the targets the policy votes on."""

PROTOCOL_OPTIONS: dict[str, dict[str, dict[str, Any]]] = {
    "maze": {"guide": CLUSTERS, "guide_noregion": CLUSTERS},
    "real_robot": {},  # every planner at its config's own defaults
}
"""protocol name -> planner name -> option -> its default at that protocol (none: the config's)."""


def protocol_name(protocol: Protocol) -> str:
    """The named protocol whose defaults `protocol` takes (see the module's docstring)."""
    for name, named in PROTOCOLS.items():
        if all(math.isclose(getattr(named, f), getattr(protocol, f), rel_tol=1e-9) for f in MODEL_INPUT_FIELDS):
            return name
    return min(PROTOCOLS, key=lambda name: abs(math.log(PROTOCOLS[name].node_resolution / protocol.node_resolution)))


def protocol_options(planner: str, protocol: Protocol | str) -> dict[str, Any]:
    """The options a protocol (or a protocol's name) gives `planner` other defaults for.

    ValueError for a name that is not one of `PROTOCOLS`."""
    if isinstance(protocol, str):
        if protocol not in PROTOCOL_OPTIONS:
            raise ValueError(f"unknown protocol {protocol!r}; choose from: {', '.join(PROTOCOL_OPTIONS)}")
        name = protocol
    else:
        name = protocol_name(protocol)
    return dict(PROTOCOL_OPTIONS[name].get(planner, {}))


def has_protocol_options(planner: str) -> bool:
    """Whether any protocol gives `planner` defaults of its own."""
    return any(planner in table for table in PROTOCOL_OPTIONS.values())
