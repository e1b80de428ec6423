"""`skyring experiment safety`: the sweep's configurations, and a sweep of two tiny runs end to end.

Kept fast: the configurations are only planned, and the end-to-end sweep flies two runs of 3 MAVs for 6 s at
10 Hz in this process, plus one of them again with the printed `skyring sim` command.
"""

import json
import shlex
from collections import Counter
from concurrent.futures import ThreadPoolExecutor

import pytest
from cli_run import run_skyring

from server.lab import experiments as exp
from server.lab import report as rep
from server.lab import safety_sweep as sweep
from server.lab.experiments import RunResult
from server.lab.safety_report import distribution, render_report, reproducible_part

PLAN = sweep.plan_sweep(base_seed=0, runs=1000)
TINY_FIRST = 84  # runs 84 and 85 of base seed 0 fly 3 MAVs each (the paper's trees, 25 % loss)


def test_run_i_is_the_same_in_a_sweep_and_alone():
    again = sweep.plan_sweep(base_seed=0, runs=3, first=500)
    assert again == PLAN[500:503]
    assert sweep.sweep_run(base_seed=0, index=17) == PLAN[17]
    assert sweep.sweep_run(base_seed=1, index=17) != PLAN[17]


def test_the_sweep_spans_every_dimension_and_half_of_it_starts_clustered():
    assert Counter(r.start for r in PLAN) == {"ring": 500, "cluster": 500}
    assert sorted({r.vehicles for r in PLAN}) == list(range(3, 17))
    assert {r.trees for r in PLAN} == set(sweep.TREE_CHOICES)
    assert {r.comm_loss for r in PLAN} == set(sweep.LINK_LOSSES)
    assert {r.person for r in PLAN} == {"paper", "random"}
    assert {r.method for r in PLAN} == {"active"}
    assert len({r.seed for r in PLAN}) == 1000
    assert {(r.duration_s, r.rate_hz, r.warmup_s) for r in PLAN} == {(90.0, 10.0, 20.0)}


def test_each_method_gets_ring_and_clustered_starts_alike():
    plan = sweep.plan_sweep(base_seed=0, runs=60, methods=("active", "dqmpc", "price"))
    assert Counter((r.method, r.start) for r in plan) == {
        (m, s): 10 for m in ("active", "dqmpc", "price") for s in ("ring", "cluster")
    }
    with pytest.raises(ValueError, match="methods"):
        sweep.plan_sweep(base_seed=0, runs=1, methods=("magic",))


def test_violations_are_counted_against_each_threshold():
    run = PLAN[0]

    def outcome(true_m, believed_m, clearance_m):
        return sweep.RunOutcome(
            run=run,
            separation=sweep.Minimum(true_m, 1.0, (1, 2)),
            believed_separation=sweep.Minimum(believed_m, 1.0, (1, 2)),
            obstacle_clearance=sweep.Minimum(clearance_m, 2.0, (1, "tree-1")),
            person_distance=sweep.Minimum(5.0, 3.0, (2,)),
        )

    limits = sweep.Thresholds()
    assert outcome(2.0, 2.0, None).violations(limits) == ()
    assert outcome(0.99, 1.49, -0.01).violations(limits) == ("believed", "true", "trunk")
    assert outcome(1.0, 1.5, 0.0).violations(limits) == ()
    failed = sweep.outcome(run, RunResult(spec=run.spec(), report=None, error="boom"))
    assert failed.violations(limits) == () and failed.separation.distance_m is None
    d = distribution([outcome(float(v), 3.0, None) for v in range(1, 101)], "separation")
    assert d is not None and (d.n, d.min_m, d.median_m) == (100, 1.0, pytest.approx(50.5))
    assert distribution([outcome(2.0, 2.0, None)], "obstacle_clearance") is None
    text = render_report([outcome(0.5, 0.7, 1.0)], command="c", thresholds=limits, figure=None, wall_s=1.0)
    assert run.sim_command() in reproducible_part(text)


def test_a_sweep_of_two_tiny_runs_writes_the_report_and_commands_that_reproduce_them(
    tmp_path, capsys, monkeypatch
):
    # The runs go through the experiments' runner as in a real sweep, but in this process: a new worker
    # process would import the simulator again, most of this test's time on a loaded machine (the process
    # pool itself is tested in test_experiments.py).
    monkeypatch.setattr(exp, "_fresh_process_pool", lambda *, jobs, simulator: ThreadPoolExecutor(jobs))
    done = run_skyring(
        capsys,
        "experiment",
        "safety",
        "--runs",
        "2",
        "--first",
        str(TINY_FIRST),
        "--duration",
        "6",
        "--seed",
        "0",
        "--jobs",
        "1",
        "--out",
        str(tmp_path),
    )
    assert done.returncode == 0, done.stderr[-2000:]
    doc = json.loads((tmp_path / "safety.json").read_text())
    assert [r["index"] for r in doc["results"]] == [TINY_FIRST, TINY_FIRST + 1]
    assert [r["config"]["vehicles"] for r in doc["results"]] == [3, 3]
    assert [r["config"]["start"] for r in doc["results"]] == ["ring", "cluster"]
    report = (tmp_path / "report.md").read_text()
    assert "## Distribution of the minima over the runs" in report and "## Violations" in report
    assert (tmp_path / "figures" / "safety_minima.png").stat().st_size > 10_000
    assert "figures/safety_minima.png" in report

    run = doc["results"][1]
    argv = shlex.split(run["sim_command"])
    assert argv[:3] == ["skyring", "sim", "--headless"]
    assert (
        sweep.sweep_run(base_seed=0, index=TINY_FIRST + 1, duration_s=6.0).sim_command() == run["sim_command"]
    )
    replay = tmp_path / "replay.json"
    again = run_skyring(capsys, *argv[1:], "--report", str(replay))
    assert again.returncode == 0, again.stderr[-2000:]
    metrics = json.loads(replay.read_text())["metrics"]
    for name in ("min_separation_m", "min_believed_separation_m", "min_person_distance_m"):
        assert metrics[name] == pytest.approx(run[name], abs=1e-9)
    assert metrics["min_separation_pair"] == run["min_separation_pair"]
    assert metrics["min_separation_t_s"] == run["min_separation_t_s"]


def test_the_experiments_tables_leave_out_when_and_between_whom_a_minimum_happened():
    assert rep.metric_kind("min_separation_m") == "result"
    assert rep.metric_kind("min_separation_t_s") == "event"
    assert rep.metric_kind("min_person_distance_vehicle") == "event"
    assert rep.metric_kind("flight_ticks") == "count"
    assert "min_separation_pair" not in rep.flatten({"min_separation_pair": [1, 2]})
