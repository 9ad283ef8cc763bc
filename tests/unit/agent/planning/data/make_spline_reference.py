"""Write spline_reference.json: `build_reference` sampled on fixed inputs, one per path.

    .venv/bin/python tests/unit/agent/planning/data/make_spline_reference.py

Each case is one set of `build_reference` keyword arguments and the `Reference` it gave
(every field, floats written exactly): the natural and the clamped cubic spline, a start
too sharp to clamp, the straight line of two points, a robot at its goal, a goal inside the
horizon, and the lines and arcs path with a start arc, without one (a sharp start) and with
corners that share short legs.

Run again only when the reference is meant to change; the test
(`tests/unit/agent/planning/test_spline.py::test_build_reference_reproduces_the_stored_samples`)
then shows what moved.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from agent.planning.spline import build_reference

OUT = Path(__file__).with_name("spline_reference.json")
FIELDS = ("t_s", "x_m", "y_m", "heading_rad", "v_mps", "omega_radps", "s_m")
V_MAX, ACCEL, DT = 1.1, 1.5, 0.1

CASES: dict[str, dict[str, object]] = {
    "spline_natural": dict(waypoints_m=[[0.0, 0.0], [2.0, -1.0], [4.0, -1.2], [6.0, 0.5],
                                        [10.0, 0.0]],
                           heading_rad=0.2, horizon_steps=30, v_start_mps=0.4),
    "spline_clamped": dict(waypoints_m=[[0.0, 0.0], [4.0, 1.0], [9.0, -2.0]],
                           heading_rad=0.1, horizon_steps=30, clamp_heading=True),
    "spline_sharp_start": dict(waypoints_m=[[0.0, 0.0], [4.0, 1.0], [9.0, -2.0]],
                               heading_rad=math.pi - 0.3, horizon_steps=20,
                               clamp_heading=True),
    "straight_line": dict(waypoints_m=[[1.0, 2.0], [11.0, 4.0]], heading_rad=-6.0,
                          horizon_steps=20, v_start_mps=0.2),
    "at_goal": dict(waypoints_m=[[3.0, -1.0], [3.0, -1.0005]], heading_rad=0.7,
                    horizon_steps=5),
    "goal_inside_horizon": dict(waypoints_m=[[0.0, 0.0], [1.0, 0.5], [2.0, 0.0]],
                                heading_rad=0.3, horizon_steps=40),
    "lines_arcs_start_arc": dict(waypoints_m=[[0.0, 0.0], [12.0, 0.0], [30.0, 6.0]],
                                 heading_rad=0.15, horizon_steps=60, v_start_mps=0.5,
                                 lines_arcs=True, corner_radius_m=1.0, start_radius_m=5.0),
    "lines_arcs_sharp_start": dict(waypoints_m=[[0.0, 0.0], [3.0, 2.0], [5.0, -1.0],
                                                [9.0, 0.0]],
                                   heading_rad=2.5, horizon_steps=60, lines_arcs=True,
                                   corner_radius_m=1.5),
    "lines_arcs_short_legs": dict(waypoints_m=[[0.0, 0.0], [4.0, 0.0], [4.5, 0.4],
                                               [4.7, 1.0], [4.6, 6.0]],
                                  heading_rad=-0.2, horizon_steps=60, lines_arcs=True,
                                  corner_radius_m=5.0, start_radius_m=3.0),
}
"""Keyword arguments of `build_reference` besides v_max_mps, accel_mps2 and dt_s."""


def main() -> None:
    cases = {}
    for name, kwargs in CASES.items():
        ref = build_reference(np.array(kwargs["waypoints_m"]), v_max_mps=V_MAX,
                              accel_mps2=ACCEL, dt_s=DT,
                              **{k: v for k, v in kwargs.items() if k != "waypoints_m"})
        expected: dict[str, object] = {f: getattr(ref, f).tolist() for f in FIELDS}
        expected["length_m"] = ref.length_m
        cases[name] = {"inputs": kwargs, "expected": expected}
    text = json.dumps({
        "comment": "build_reference on fixed inputs and the Reference it gave; written by "
                   "make_spline_reference.py beside this file.",
        "v_max_mps": V_MAX, "accel_mps2": ACCEL, "dt_s": DT,
        "tolerance": {"atol": 1e-9,
                      "what": "m, rad, m/s, rad/s, s: round-off of another numpy or libm "
                              "build (the same build gives the same floats)"},
        "cases": cases,
    }, indent=1)
    # Lists of numbers on one line each: [0.0, 0.1, ...].
    text = re.sub(r"\[\s+([^\[\]{}]*?)\s+\]",
                  lambda m: "[" + re.sub(r",\s+", ", ", m.group(1)) + "]", text)
    OUT.write_text(text + "\n")
    print(f"wrote {OUT}: {len(cases)} cases")


if __name__ == "__main__":
    main()
