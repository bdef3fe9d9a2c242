"""The paper's published numbers (Tables II-V) and the row names of our planners in them.

Constants only: the tables of `pipeline.reporting.tables` set these beside ours, and the
markdown of `pipeline.reporting.table_markdown` prints them.
"""

from __future__ import annotations

import numpy as np

DASH = "—"  # a cell with no number: the paper has no such row, or ours is not finite

# Table II: distance (m) to complete exploration and its gap to the optimal path (%), maze benchmark.
PAPER_TABLE2: dict[str, tuple[float, float | None]] = {
    "NBVP": (640.0, 27.7),
    "DRL": (575.0, 14.8),
    "MapEx": (571.0, 14.0),
    "DARE": (565.0, 12.8),
    "TARE": (560.0, 11.8),
    "GUIDE": (545.0, 8.8),
    "Optimal": (501.0, None),
}
# Table III: ablations, distance (m) and gap to optimal (%).
PAPER_TABLE3: dict[str, tuple[float, float | None]] = {
    "w/o region evaluation": (561.0, 11.9),
    "w/o diffusion": (580.0, 15.7),
    "GUIDE": (545.0, 8.8),
}
# Table IV: denoising steps K -> (decision time in s, distance in m), Gazebo scenes.
PAPER_TABLE4: dict[str, dict[int, tuple[float, float]]] = {
    "GUIDE": {10: (0.177, 579.0), 30: (0.227, 533.0), 50: (0.663, 532.0), 100: (1.283, 530.0)},
    "DARE": {10: (0.163, 762.0), 30: (0.211, 747.0), 50: (0.647, 724.0), 100: (1.271, 708.0)},
}
# Table V: two Gazebo scenes (3-D, 5 runs each): scene -> method -> (distance m, time s, m^3/m, m^3/s).
PAPER_TABLE5: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "Scene 1 (64 x 85 m)": {
        "TARE": (1064.72, 585.53, 5.11, 9.29),
        "DRL": (741.15, 536.77, 7.34, 10.13),
        "DARE": (681.41, 482.82, 7.98, 11.27),
        "GUIDE": (537.18, 432.11, 10.13, 12.59),
    },
    "Scene 2 (92 x 74 m)": {
        "TARE": (1033.72, 615.37, 6.58, 11.06),
        "DRL": (759.88, 635.36, 8.96, 10.72),
        "DARE": (797.38, 623.27, 8.54, 10.93),
        "GUIDE": (531.37, 513.09, 12.81, 13.27),
    },
}
# Our registered planner names -> the paper's row names (planners without a row show DASH).
PAPER_ROWS: dict[str, str] = {
    "nbvp": "NBVP",
    "drl": "DRL",
    "drl_shipped": "DRL",  # params.yaml's label for the shipped drl policy (trained longer than the default profile's)
    "mapex": "MapEx",
    "dare": "DARE",
    "tare": "TARE",
    "guide": "GUIDE",
    "optimal": "Optimal",
    "guide_noregion": "w/o region evaluation",
    "guide_tsp": "w/o diffusion",
}


def paper_row(planner: str) -> str:
    """The paper's row name for one of our planners, else DASH."""
    return PAPER_ROWS.get(str(planner), DASH)


def paper_table2_or_3(planner: str, prefer: str = "Table III") -> tuple[float, float, str]:
    """(distance m, gap %, source) from the preferred table (Table II or III), else the other;
    NaNs and '' when the paper has no row."""
    row = paper_row(planner)
    tables = [("Table II", PAPER_TABLE2), ("Table III", PAPER_TABLE3)]
    if prefer == "Table III":
        tables.reverse()
    for source, table in tables:
        if row in table:
            distance, gap = table[row]
            return distance, (np.nan if gap is None else gap), source
    return np.nan, np.nan, ""
