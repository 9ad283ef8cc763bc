"""System test: the router-link benchmark's run, real processes on loopback (small).

Two robots on host A (the world's router), two on host B behind a relay router that dials
the world through the counting proxy (`orchestrator.experiments.router_link.run_case`).
Checked: bytes crossed the link both ways in the control phase, the relay used one link and
dialled nothing but the proxy, both routers ran with TLS and access control, and without a
relay each robot of host B dials the link itself. No figure is held to a budget (the
measured table is in docs/scale.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.experiments.router_link import run_case
from tests.system.test_distributed import processes_of_run

pytestmark = [pytest.mark.system, pytest.mark.timeout(120)]


@pytest.mark.parametrize("case", ["near", "direct"])
def test_bytes_cross_the_counted_link(tmp_path: Path, case: str) -> None:
    row = run_case(4, case, time_scale=1.0, seconds=2.0, out_root=tmp_path,
                   startup_timeout_s=30.0, host_b_robots=2)
    assert row["sim_s"] == pytest.approx(2.0, abs=0.05), row
    assert row["link_down_bytes_s"] > 0 and row["link_up_bytes_s"] > 0, row
    assert row["host_b_robots"] == 2 and row["border_robots"] == 2, row
    if case == "near":
        assert row["links"] == 1, row
        assert row["relay_dialled_only_link"] and row["relay_dialled"], row
        assert row["acl_routers"] == ["world", "router-b"], row
    else:
        assert row["links"] == 2, row  # each robot of host B
        assert row["acl_routers"] == ["world"], row
    assert not processes_of_run(row["run_id"]), "orphan processes left behind"
