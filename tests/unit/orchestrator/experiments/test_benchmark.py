"""The benchmark suite: cases, named seed sets, selection, and the table's aggregation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from orchestrator.experiments import benchmark as bm
from orchestrator.experiments import liveness_families
from orchestrator.experiments.families import FAMILIES, SETUPS


def test_tuning_and_evaluation_seeds_are_disjoint_and_enough():
    assert not set(bm.TUNING_SEEDS) & set(bm.EVALUATION_SEEDS)
    assert len(bm.EVALUATION_SEEDS) >= 10 and len(bm.TUNING_SEEDS) >= 6
    assert len(set(bm.EVALUATION_SEEDS)) == len(bm.EVALUATION_SEEDS)
    assert set(bm.QUICK_SEEDS) <= set(bm.EVALUATION_SEEDS)
    # A count never reaches into the tuning seeds.
    assert not set(bm.parse_seeds(str(min(bm.TUNING_SEEDS)))) & set(bm.TUNING_SEEDS)


def test_the_suite_covers_every_benchmark_family_and_the_setups():
    families = set(bm.family_names())
    assert families == {"circle", "circle_mixed", "crossing_45", "crossing_90", "crossing_135",
                        "swap_pairs", "swap_grid", "random_sparse", "random_medium",
                        "random_dense", "obstacles_circle", "setups", *bm.LIVENESS_FAMILIES}
    assert set(bm.LIVENESS_FAMILIES) == set(liveness_families.GENERATORS)
    assert {c.scenario for c in bm.SUITE if c.family == "setups"} == set(SETUPS)
    assert [c.agents for c in bm.SUITE if c.family == "circle"] == [8, 16, 24, 32, 48]
    labels = [c.label for c in bm.SUITE]
    assert len(labels) == len(set(labels))
    assert all(c.scenario in FAMILIES or c.scenario in SETUPS for c in bm.SUITE)
    assert "circle_mixed_32" in labels and "crossing_90_16" in labels
    assert "swap_grid_16" in labels and "random_dense_20" in labels
    for label in ("wall_door_12", "wall_doors_16", "corridor_8", "grid_dense_16",
                  "grid_dense_25", "pillar_circle_24", "pillar_circle_40", "random_40_40",
                  "platoons_18", "crossing_60_mixed_16"):
        assert label in labels


def test_every_case_resolves_with_the_jitter():
    for case in (*bm.SUITE, *bm.QUICK_SUITE):
        for seed in (bm.EVALUATION_SEEDS[-1], bm.TUNING_SEEDS[0]):
            job = bm.Job(case, "orca", seed, "lockstep", Path("x"))
            s = job.scenario()
            assert case.agents is None or len(s.robots) == case.agents
            assert {r.planner for r in s.robots} == {"orca"}


def test_quick_suite_is_small():
    assert len(bm.QUICK_SUITE) <= 10
    assert all((c.agents or 0) <= 8 for c in bm.QUICK_SUITE)
    assert {c.family for c in bm.QUICK_SUITE} <= set(bm.family_names())


def test_select_cases_by_family_alias_setup_and_label():
    assert bm.select_cases(bm.SUITE, "all") == bm.SUITE
    crossing = bm.select_cases(bm.SUITE, ["crossing"])
    assert [c.label for c in crossing] == ["crossing_45_16", "crossing_90_16",
                                           "crossing_135_16", "crossing_60_mixed_16"]
    liveness = bm.select_cases(bm.SUITE, ["liveness"])
    assert {c.family for c in liveness} == set(bm.LIVENESS_FAMILIES) and len(liveness) == 10
    assert [c.label for c in bm.select_cases(bm.SUITE, ["walls"])] == \
        ["wall_door_12", "wall_doors_16", "corridor_8"]
    assert [c.label for c in bm.select_cases(bm.SUITE, ["circle"])] == \
        ["circle_8", "circle_16", "circle_24", "circle_32", "circle_48"]
    picked = bm.select_cases(bm.SUITE, ["setup_b", "circle_24"])
    assert [c.label for c in picked] == ["circle_24", "setup_b"]  # suite order
    assert len(bm.select_cases(bm.SUITE, ["setups"])) == 7
    with pytest.raises(ValueError, match="selects no case"):
        bm.select_cases(bm.SUITE, ["circlez"])


def test_plan_jobs_gives_every_run_its_own_directory(tmp_path):
    jobs = bm.plan_jobs(bm.QUICK_SUITE, ["eifp-mpc", "orca"], (0, 1), mode="lockstep",
                        out=tmp_path)
    assert len(jobs) == len(bm.QUICK_SUITE) * 4
    assert len({j.out_dir for j in jobs}) == len(jobs)
    assert all(j.out_dir.parent == tmp_path / "runs" for j in jobs)
    assert jobs[0].out_dir.name == "setup_a-eifp-mpc-s0"


def fake(case, planner, seed, *, success=True, osc=(0, 1), arrived=None, contacts=0,
         gap=0.3, path=1.1, time_ratio=1.2, p50=0.5, p99=5.0, error=None, family="fam"):
    n = len(osc)
    return {"family": family, "case": case, "planner": planner, "seed": seed,
            "robots": n, "arrived": n if arrived is None else arrived, "success": success,
            "contacts": contacts, "min_gap_m": gap,
            "oscillations_per_robot": sum(osc) / n, "oscillations_max": max(osc),
            "robot_oscillations": list(osc), "path_ratio_mean": path,
            "time_ratio_mean": time_ratio, "plan_ms_p50": p50, "plan_ms_p99": p99,
            "error": error}


def test_summarize_pools_the_robots_oscillations_over_the_seeds():
    records = [
        fake("c", "a", 0, osc=(0, 1, 2, 9)),
        fake("c", "a", 1, osc=(1, 1, 3, 4), success=False, arrived=3, contacts=2, gap=-0.1,
             time_ratio=None, p50=0.7, p99=9.0),
        fake("c", "b", 0, osc=(0, 0)),
        fake("d", "a", 0, osc=(5, 5), family="other"),
    ]
    rows = bm.summarize(records, case_order=["c", "d"], planner_order=["a", "b"])
    assert [(r["case"], r["planner"]) for r in rows] == [("c", "a"), ("c", "b"), ("d", "a")]
    r = rows[0]
    assert r["runs"] == 2 and r["success_rate"] == 0.5
    assert r["osc_per_robot_median"] == 1.5  # of 0,1,2,9,1,1,3,4
    assert r["osc_per_robot_max"] == 9
    assert r["arrived_rate"] == pytest.approx(7 / 8)
    assert r["contacts"] == 2 and r["min_gap_m"] == -0.1
    assert r["time_ratio_mean"] == pytest.approx(1.2)  # the run without a value is left out
    assert r["path_ratio_mean"] == pytest.approx(1.1)
    assert r["plan_ms_p50"] == pytest.approx(0.6) and r["plan_ms_p99"] == 9.0
    assert r["errors"] == 0 and r["seeds"] == [0, 1] and r["family"] == "fam"
    assert rows[1]["osc_per_robot_median"] == 0 and rows[1]["success_rate"] == 1.0
    assert rows[2]["family"] == "other"


def test_summarize_counts_a_broken_run_as_a_failure():
    records = [fake("c", "a", 0, osc=(2, 4)),
               bm.run_record(bm.Job(bm.Case("fam", "c"), "a", 1, "lockstep", Path("x")),
                             None, wall_s=1.0, error="RuntimeError: boom")]
    (row,) = bm.summarize(records)
    assert row["runs"] == 2 and row["errors"] == 1 and row["success_rate"] == 0.5
    assert row["osc_per_robot_median"] == 3.0 and row["osc_per_robot_max"] == 4


def test_summarize_falls_back_to_the_run_figures_without_per_robot_counts():
    rec = fake("c", "a", 0, osc=(1, 3))
    rec["robot_oscillations"] = []
    (row,) = bm.summarize([rec])
    assert row["osc_per_robot_max"] == 3


def test_run_record_keeps_the_per_robot_oscillations():
    job = bm.Job(bm.Case("circle", "circle", 8), "orca", 2, "lockstep", Path("out/r"))
    metrics = {"robots": 2, "arrived": 2, "success": True, "oscillations_max": 3,
               "per_robot": [{"oscillations": 3}, {"oscillations": 0}]}
    rec = bm.run_record(job, metrics, wall_s=1.23456, ideal_s=30.0)
    assert rec["case"] == "circle_8" and rec["family"] == "circle" and rec["seed"] == 2
    assert rec["robot_oscillations"] == [3, 0] and rec["oscillations_max"] == 3
    assert rec["error"] is None and rec["wall_s"] == 1.235
    assert bm.run_record(job, None, wall_s=0.0, world_status=139)["error"].endswith("139)")


def test_tables_have_one_line_per_row_and_the_columns():
    rows = bm.summarize([fake("c", "a", 0), fake("c", "b", 0, success=False, time_ratio=None)])
    text = bm.format_text(rows).splitlines()
    assert len(text) == 2 + len(rows)
    assert "osc/robot p50" in text[0] and "plan ms p99" in text[0]
    md = bm.format_markdown(rows, caption="cap").splitlines()
    assert md[0] == "cap" and md[2].startswith("| family | planner | runs | success")
    assert md[3].startswith("|---|---|---:|")
    assert md[4].startswith("| c | a | 1 | 100 % |")
    assert md[5].startswith("| c | b | 1 | 0 % |") and " - |" in md[5]
    assert all(line.count("|") == len(bm.COLUMNS) + 1 for line in md[2:6])


def test_write_outputs(tmp_path):
    rows = bm.summarize([fake("c", "a", 0), fake("c", "b", 0)])
    paths = bm.write_outputs(tmp_path, rows, [fake("c", "a", 0)],
                             {"mode": "lockstep", "seeds": [0], "seed_set": "quick"})
    assert [p.name for p in paths] == ["benchmark.csv", "benchmark.json", "benchmark.md",
                                       "benchmark.png"]
    assert all(p.stat().st_size > 0 for p in paths)
    header = (tmp_path / "benchmark.csv").read_text().splitlines()[0].split(",")
    assert header[:3] == ["case", "planner", "runs"]
    assert len((tmp_path / "benchmark.csv").read_text().splitlines()) == 1 + len(rows)
    saved = json.loads((tmp_path / "benchmark.json").read_text())
    assert saved["rows"] == rows and saved["suite"]["seed_set"] == "quick"
    assert "| c | b |" in (tmp_path / "benchmark.md").read_text()


def test_the_readme_results_section_is_replaced_between_its_markers() -> None:
    import pytest

    from orchestrator.experiments.benchmark import RESULTS_BEGIN, RESULTS_END, replace_results

    readme = f"# x\n\n## Results\n{RESULTS_BEGIN}\nold table\n{RESULTS_END}\n\n## After\n"
    new = replace_results(readme, "| a | b |\n", "orchestrator benchmark --quick")
    assert "old table" not in new and "| a | b |" in new
    assert "Generated by `orchestrator benchmark --quick`" in new
    assert new.endswith(f"{RESULTS_END}\n\n## After\n") and new.startswith("# x\n")
    assert replace_results(new, "| c |\n", "cmd").count(RESULTS_BEGIN) == 1
    with pytest.raises(ValueError, match="expected"):
        replace_results("no markers", "| a |", "cmd")


def test_the_readme_command_leaves_out_where_the_run_was_written() -> None:
    from orchestrator.experiments.benchmark import portable_command

    argv = ["benchmark", "--planners", "eifp-mpc,orca", "--out", "/tmp/x", "--jobs", "2",
            "--readme=README.md"]
    assert portable_command(argv) == "orchestrator benchmark --planners eifp-mpc,orca --jobs 2"


def test_the_readme_summary_groups_families_and_puts_planners_side_by_side() -> None:
    from orchestrator.experiments.benchmark import format_readme_summary

    def row(family: str, case: str, planner: str, success: float, osc: float, worst: float,
            time_ratio: float | None, contacts: int = 0) -> dict:
        return {"family": family, "case": case, "planner": planner, "runs": 5,
                "success_rate": success, "contacts": contacts, "osc_per_robot_median": osc,
                "osc_per_robot_max": worst, "time_ratio_mean": time_ratio}

    rows = [row("circle", "circle_8", "eifp-mpc", 1.0, 4, 9, 1.1),
            row("circle", "circle_16", "eifp-mpc", 1.0, 8, 12, 1.3),
            row("circle", "circle_8", "orca", 0.0, 0, 0, None),
            row("circle", "circle_16", "orca", 0.4, 2, 50, 2.0, contacts=1)]
    text = format_readme_summary(rows)
    lines = text.strip().splitlines()
    assert "eifp-mpc:" in lines[0] and "orca:" in lines[0]
    circles = next(line for line in lines if line.startswith("| antipodal circles"))
    assert "| 10/10, 0, 6 (12), 1.20 |" in circles  # median of 4 and 8; worst 12; mean time
    assert "| 2/10, 1, 1 (50), 2.00 |" in circles
    assert "| setups A-G | - | - |" in text  # a group with no runs says so


# --------------------------------------------------------------------------------------
# Per-robot statistics and the targets
# --------------------------------------------------------------------------------------

def test_run_record_keeps_every_robots_ratios_and_the_split_gaps():
    job = bm.Job(bm.Case("wall_door", "wall_door", 12), "eifp-mpc", 0, "lockstep", Path("r"))
    metrics = {"robots": 2, "arrived": 1, "min_gap_m": 0.1, "min_gap_robots_m": 0.3,
               "min_gap_obstacles_m": 0.1,
               "per_robot": [{"oscillations": 2, "time_ratio": 1.4, "path_ratio": 1.05},
                             {"oscillations": 7, "time_ratio": None, "path_ratio": None}]}
    rec = bm.run_record(job, metrics, wall_s=1.0)
    assert rec["robot_time_ratios"] == [1.4, None] and rec["robot_path_ratios"] == [1.05, None]
    assert rec["min_gap_robots_m"] == 0.3 and rec["min_gap_obstacles_m"] == 0.1


def robots_run(case, planner, seed, *, osc, time_ratios, path_ratios=None, family="fam",
               success=True, contacts=0, gap_rr=0.3, gap_ro=None, error=None):
    n = len(osc)
    arrived = sum(1 for t in time_ratios if t is not None)
    return {"family": family, "case": case, "planner": planner, "seed": seed, "robots": n,
            "arrived": arrived, "success": success, "contacts": contacts,
            "min_gap_m": min(g for g in (gap_rr, gap_ro) if g is not None),
            "min_gap_robots_m": gap_rr, "min_gap_obstacles_m": gap_ro,
            "robot_oscillations": list(osc), "robot_time_ratios": list(time_ratios),
            "robot_path_ratios": list(path_ratios or [1.0 if t else None
                                                      for t in time_ratios]),
            "oscillations_per_robot": sum(osc) / n, "oscillations_max": max(osc),
            "time_ratio_mean": None, "path_ratio_mean": None, "error": error}


def test_summarize_gives_median_and_p95_per_robot_over_every_robot_of_every_run():
    # 20 robots over two runs: reversals 0..19; time ratios of the 18 that arrived.
    times = [1.0 + 0.1 * k for k in range(10)]
    runs = [robots_run("c", "a", 0, osc=range(10), time_ratios=times,
                       path_ratios=[1.0] * 9 + [1.5]),
            robots_run("c", "a", 1, osc=range(10, 20), time_ratios=times[:8] + [None, None],
                       gap_rr=0.2, gap_ro=-0.01)]
    (row,) = bm.summarize(runs)
    assert row["osc_per_robot_median"] == 9.5
    assert row["osc_per_robot_p95"] == pytest.approx(18.05)  # linear between 18 and 19
    assert row["osc_per_robot_max"] == 19
    arrived = times + times[:8]
    assert row["time_ratio_median"] == pytest.approx(1.4)  # 9th and 10th of 18: 1.4, 1.4
    assert row["time_ratio_p95"] == pytest.approx(float(np.percentile(arrived, 95)))
    assert row["path_ratio_median"] == 1.0
    assert row["path_ratio_p95"] == pytest.approx(float(np.percentile([1.0] * 17 + [1.5], 95)))
    assert row["arrived_rate"] == pytest.approx(18 / 20)
    assert row["min_gap_robots_m"] == 0.2 and row["min_gap_obstacles_m"] == -0.01
    assert row["min_gap_m"] == -0.01


def test_summarize_uses_the_run_means_for_records_without_per_robot_ratios():
    old = fake("c", "a", 0, osc=(1, 3), time_ratio=1.4, path=1.2)  # an older record
    (row,) = bm.summarize([old])
    assert row["time_ratio_median"] == 1.4 and row["path_ratio_p95"] == pytest.approx(1.2)
    assert row["min_gap_robots_m"] is None and row["min_gap_obstacles_m"] is None


GOOD = {"family": "circle", "planner": "eifp-mpc", "runs": 10, "success_rate": 1.0,
        "arrived_rate": 1.0, "contacts": 0, "min_gap_m": 0.06, "min_gap_robots_m": 0.06,
        "min_gap_obstacles_m": None, "osc_per_robot_median": 2.0, "osc_per_robot_p95": 6.0,
        "time_ratio_median": 1.3, "path_ratio_median": 1.15, "errors": 0}


def test_a_row_on_every_limit_meets_the_targets():
    assert bm.target_misses(GOOD) == []


@pytest.mark.parametrize(("change", "miss"), [
    ({"arrived_rate": 23 / 25}, "arrived 92 %"),
    ({"arrived_rate": None}, "arrived -"),
    ({"contacts": 2}, "contacts 2"),
    ({"min_gap_robots_m": 0.049}, "gap r-r 0.049 < 0.05"),
    ({"min_gap_obstacles_m": -0.002}, "gap r-o -0.002 < 0.05"),
    ({"min_gap_robots_m": None, "min_gap_m": 0.01}, "gap 0.010 < 0.05"),
    ({"osc_per_robot_median": 2.5}, "osc p50 2.5 > 2"),
    ({"osc_per_robot_p95": 6.2}, "osc p95 6.2 > 6"),
    ({"time_ratio_median": 1.31}, "time p50 1.31 > 1.3"),
    ({"path_ratio_median": 1.2}, "path p50 1.20 > 1.15"),
    ({"errors": 1}, "errors 1"),
])
def test_each_target_is_checked(change, miss):
    assert bm.target_misses({**GOOD, **change}) == [miss]


def test_grids_doorways_and_the_corridor_get_more_time_and_crowds_more_reversals():
    row = {**GOOD, "osc_per_robot_median": 3.0, "time_ratio_median": 1.5}
    for family in ("grid_dense", "swap_grid", "wall_door", "wall_doors", "corridor"):
        assert bm.target_misses({**row, "family": family}) == []
    for family in ("pillar_circle", "random_40", "platoons", "obstacles_circle"):
        assert bm.target_misses({**row, "family": family}) == ["time p50 1.50 > 1.3"]
    for family in ("circle", "crossing_60_mixed", "crossing_90", "setups"):
        assert bm.target_misses({**row, "family": family}) == ["osc p50 3 > 2",
                                                              "time p50 1.50 > 1.3"]


def test_the_reference_planner_sets_success_and_time_targets():
    orca = {**GOOD, "planner": "orca", "time_ratio_median": 1.0}
    assert bm.target_misses({**GOOD, "time_ratio_median": 1.2}, orca) == []
    assert bm.target_misses({**GOOD, "time_ratio_median": 1.25}, orca) == [
        "time vs orca 1.25 > 1.2"]
    assert bm.target_misses({**GOOD, "success_rate": 0.9, "time_ratio_median": 1.25},
                            orca) == ["success 90 % < orca 100 %"]
    # Where the reference fails too, only the planner's own targets count.
    assert bm.target_misses({**GOOD, "success_rate": 0.9},
                            {**orca, "success_rate": 0.5, "time_ratio_median": 0.5}) == []


def test_summarize_writes_the_targets_cell_against_orca():
    runs = [robots_run("c", "eifp-mpc", 0, osc=(0, 1), time_ratios=(1.1, 1.2),
                       family="circle"),
            robots_run("c", "orca", 0, osc=(0, 0), time_ratios=(1.0, 1.0), family="circle"),
            robots_run("d", "eifp-mpc", 0, osc=(5, 9), time_ratios=(1.1, None),
                       family="wall_door", success=False, gap_ro=0.01)]
    rows = bm.summarize(runs)
    assert [r["targets"] for r in rows] == [
        "ok", "ok", "arrived 50 %; gap r-o 0.010 < 0.05; osc p50 7 > 3; osc p95 8.8 > 6"]
    assert rows[2]["target_misses"][0] == "arrived 50 %"
    header, cells = bm.table_cells(rows)
    assert header[-1] == "targets" and cells[0][-1] == "ok"
    assert cells[2][header.index("gap r-o m")] == "0.010"
    assert cells[0][header.index("gap r-o m")] == "-"  # no obstacle in that case
