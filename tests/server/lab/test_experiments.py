"""`skyring experiment`: protocol, seeds, statistics, claims, figures, and the paper's orderings on real runs.

The unit tests use hand-made metric values; the acceptance tests run the real simulator in worker
processes: `skyring experiment all --quick` through the real command line (and one family of it again), and
a larger fixed-seed profile (ORDERING_*) on which the paper's orderings must hold.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_run import run_skyring

from server.lab import experiments as exp
from server.lab import figures
from server.lab import report as rep

REPO = Path(__file__).resolve().parents[3]


# ---- protocol ----------------------------------------------------------------------------------------------


def test_methods_protocol_is_se1_to_se4_with_5_mavs_and_30_runs_of_120_and_180_s():
    p = exp.paper_protocol("methods")
    methods = [dict(c.settings)["method"] for c in p.conditions]
    assert methods == ["price", "dqmpc", "active", "active"]
    assert [dict(c.settings)["virtual_obstacles"] for c in p.conditions] == ["none", "none", "none", "paper"]
    assert {dict(c.settings)["trees"] for c in p.conditions} == {"none"}
    assert {dict(c.settings)["vehicles"] for c in p.conditions} == {5}
    assert p.durations_s == (120.0,) * 10 + (180.0,) * 20


def test_scalability_protocol_sweeps_3_to_16_mavs_with_trees_10_runs_each():
    p = exp.paper_protocol("scalability")
    assert [dict(c.settings)["vehicles"] for c in p.conditions] == list(range(3, 17))
    assert {dict(c.settings)["trees"] for c in p.conditions} == {"paper"}
    assert p.runs == 10


def test_commloss_protocol_sweeps_the_papers_loss_levels_with_8_mavs_3_runs_each():
    p = exp.paper_protocol("commloss")
    losses = [dict(c.settings)["comm_loss"] for c in p.conditions]
    assert losses == pytest.approx([0.0, 0.10, 0.25, 0.50, 0.75, 0.90, 1.0], abs=1e-12)
    assert {dict(c.settings)["vehicles"] for c in p.conditions} == {8}
    assert p.runs == 3


def test_obstacles_protocol_sweeps_0_to_20_obstacles_with_5_mavs_5_runs_of_180_s():
    p = exp.paper_protocol("obstacles")
    assert [c.x for c in p.conditions] == [0.0, 5.0, 10.0, 15.0, 20.0]
    assert [dict(c.settings)["trees"] for c in p.conditions] == ["none", "5", "10", "15", "20"]
    assert {dict(c.settings)["vehicles"] for c in p.conditions} == {5}
    assert p.durations_s == (180.0,) * 5


def test_methods_family_starts_every_team_side_by_side():
    assert {dict(c.settings)["start"] for c in exp.paper_protocol("methods").conditions} == {"cluster"}


def test_papers_protocol_runs_every_family_at_the_papers_100_hz():
    for family in exp.FAMILIES:
        specs = exp.plan_runs([exp.paper_protocol(family)], base_seed=0)
        assert {s.config_fields()["rate_hz"] for s in specs} == {100.0}


def test_quick_profile_runs_at_the_mpcs_10_hz_step():
    for family in exp.FAMILIES:
        assert exp.quick_protocol(family).rate_hz == 10.0


def test_rate_10_runs_the_papers_protocol_at_the_mpcs_step():
    p = exp.with_overrides(exp.paper_protocol("methods"), exp.ProfileOverrides(rate_hz=10.0))
    assert {s.config_fields()["rate_hz"] for s in exp.plan_runs([p], base_seed=0)} == {10.0}


def test_rate_override_reaches_every_runs_simulator_config():
    p = exp.with_overrides(exp.paper_protocol("commloss"), exp.ProfileOverrides(rate_hz=20.0))
    assert {s.config_fields()["rate_hz"] for s in exp.plan_runs([p], base_seed=0)} == {20.0}


def test_quick_profile_keeps_every_family_with_fewer_conditions_and_short_runs():
    for family in exp.FAMILIES:
        quick, paper = exp.quick_protocol(family), exp.paper_protocol(family)
        assert 2 <= len(quick.conditions) <= len(paper.conditions)
        assert sum(quick.durations_s) * len(quick.conditions) < 0.1 * sum(paper.durations_s) * len(
            paper.conditions
        )


def test_run_override_keeps_the_papers_mix_of_short_and_long_runs():
    p = exp.with_overrides(exp.paper_protocol("methods"), exp.ProfileOverrides(runs=3))
    assert p.durations_s == (120.0, 180.0, 180.0)


def test_duration_override_applies_to_every_run():
    p = exp.with_overrides(exp.paper_protocol("methods"), exp.ProfileOverrides(runs=4, duration_s=12.5))
    assert p.durations_s == (12.5,) * 4


@pytest.mark.parametrize(
    "overrides",
    [
        exp.ProfileOverrides(runs=0),
        exp.ProfileOverrides(duration_s=-1.0),
        exp.ProfileOverrides(duration_s=math.nan),
    ],
)
def test_bad_overrides_are_refused_with_a_message(overrides):
    with pytest.raises(ValueError, match="runs|duration"):
        exp.with_overrides(exp.paper_protocol("methods"), overrides)


def test_unknown_family_is_refused_naming_the_choices():
    with pytest.raises(ValueError, match="methods, scalability, commloss, obstacles"):
        exp.select_families("wind")


def test_all_selects_the_four_families_in_the_papers_order():
    assert exp.select_families("all") == ("methods", "scalability", "commloss", "obstacles")


# ---- seeds -------------------------------------------------------------------------------------------------


def test_run_i_of_every_condition_in_a_family_shares_one_seed():
    specs = exp.plan_runs([exp.paper_protocol("commloss")], base_seed=7)
    for i in range(3):
        assert len({s.seed for s in specs if s.run_index == i}) == 1


def test_runs_and_families_get_distinct_seeds():
    specs = exp.plan_runs([exp.paper_protocol(f) for f in exp.FAMILIES], base_seed=7)
    keys = {(s.family, s.run_index) for s in specs}
    assert len({s.seed for s in specs}) == len(keys) == 30 + 10 + 3 + 5


def test_a_runs_seed_does_not_depend_on_which_other_families_are_planned():
    alone = exp.plan_runs([exp.paper_protocol("commloss")], base_seed=3)
    together = [
        s
        for s in exp.plan_runs([exp.paper_protocol(f) for f in exp.FAMILIES], base_seed=3)
        if s.family == "commloss"
    ]
    assert [s.seed for s in alone] == [s.seed for s in together]


def test_base_seed_changes_every_derived_seed():
    a = exp.plan_runs([exp.quick_protocol("methods")], base_seed=0)
    b = exp.plan_runs([exp.quick_protocol("methods")], base_seed=1)
    assert all(x.seed != y.seed for x, y in zip(a, b, strict=True))


def test_derived_seed_is_a_pure_function_of_its_inputs():
    kw = {"base_seed": 11, "family": "methods", "run_index": 4}
    assert exp.derive_seed(**kw) == exp.derive_seed(**kw)
    assert exp.derive_seed(**kw) != exp.derive_seed(**{**kw, "run_index": 5})


def test_run_files_are_laid_out_by_family_condition_and_run_index():
    spec = exp.plan_runs([exp.quick_protocol("commloss")], base_seed=0)[3]
    assert spec.relative_path() == Path("commloss/25-loss/run-001.json")


def test_resume_reuses_a_finished_run_only_for_the_same_simulator_config(tmp_path):
    spec = exp.plan_runs([exp.quick_protocol("obstacles")], base_seed=0)[0]
    exp.write_run(
        exp.RunResult(spec=spec, report={"config": {}, "metrics": {"in_frame_fraction": 0.5}}), tmp_path
    )
    loaded = exp.load_run(spec, tmp_path)
    assert loaded is not None and loaded.report is not None
    assert loaded.report["metrics"] == {"in_frame_fraction": 0.5}
    assert exp.load_run(dataclasses.replace(spec, duration_s=spec.duration_s + 1.0), tmp_path) is None


def test_resume_does_not_reuse_a_failed_run(tmp_path):
    spec = exp.plan_runs([exp.quick_protocol("obstacles")], base_seed=0)[0]
    exp.write_run(exp.RunResult(spec=spec, report=None, error="RuntimeError: boom"), tmp_path)
    assert exp.load_run(spec, tmp_path) is None


# ---- statistics --------------------------------------------------------------------------------------------


def _loaded_kernel_signatures() -> int:
    """In a pool's worker, before it has run anything: how many compiled forms the external inputs' kernel
    holds (numba loads a kernel from its cache on its first call in a process, so 0 means not loaded)."""
    from controller import fields_kernel

    return len(fields_kernel._kernel.signatures)


def test_a_runs_fresh_process_starts_with_the_compiled_kernels_loaded():
    pool = exp._fresh_process_pool(jobs=1, simulator=exp.SIMULATION_MODULE)
    try:
        assert pool.submit(_loaded_kernel_signatures).result(timeout=120) >= 1
    finally:
        pool.shutdown()


def test_describe_ignores_non_finite_values_and_gives_quartiles():
    s = rep.describe([4.0, 1.0, math.nan, 3.0, 2.0, math.inf])
    assert s is not None
    assert s.n == 4
    assert (s.mean, s.median, s.q25, s.q75) == pytest.approx((2.5, 2.5, 1.75, 3.25), abs=1e-12)
    assert s.iqr == pytest.approx(1.5, abs=1e-12)
    assert s.std == pytest.approx(np.std([1, 2, 3, 4], ddof=1), abs=1e-12)


def test_describe_of_no_finite_value_is_none():
    assert rep.describe([math.nan, None, math.inf]) is None


def test_flatten_names_nested_metrics_with_dots_and_drops_non_numbers():
    flat = rep.flatten(
        {
            "tracking_error_m": {"mean": 1, "p90": 2.5},
            "min_obstacle_clearance_m": None,
            "in_frame_fraction": 0.5,
        }
    )
    assert flat == {"tracking_error_m.mean": 1.0, "tracking_error_m.p90": 2.5, "in_frame_fraction": 0.5}


def test_metrics_are_sorted_into_results_timings_and_counters():
    kinds = [
        rep.metric_kind(m)
        for m in (
            "tick_ms.p99",
            "realtime_factor",
            "counters.braking_ticks",
            "frames",
            "tracking_error_m.mean",
            "in_frame_fraction",
        )
    ]
    assert kinds == ["timing", "timing", "count", "count", "result", "result"]


# ---- claims, on hand-made runs -----------------------------------------------------------------------------


def _fake_results(protocol: exp.Protocol, metrics_of) -> list[exp.RunResult]:
    """A result per run of `protocol` with the metrics `metrics_of(condition, run_index)` returns."""
    return [
        exp.RunResult(spec=s, report={"config": {}, "metrics": metrics_of(s.condition, s.run_index)})
        for s in exp.plan_runs([protocol], base_seed=0)
    ]


def _metrics(error: float, cov: float = 1.0, in_frame: float = 0.95) -> dict:
    return {
        "tracking_error_m": {"mean": error},
        "cov_trace_m2": {"mean": cov},
        "in_frame_fraction": in_frame,
        "center_offset_px": {"mean": 100.0},
        "spacing_error_deg": 10.0 * cov,
        "tick_ms": {"median": 1.0},
    }


def _verdicts(protocol: exp.Protocol, metrics_of) -> list[bool | None]:
    return [c.agrees for c in rep.check_claims(rep.summarize(protocol, _fake_results(protocol, metrics_of)))]


def test_methods_claims_agree_when_active_has_the_lowest_uncertainty_and_keeps_the_person_in_frame():
    cov = {"price": 2.0, "dqmpc": 1.5, "active": 0.5}
    verdicts = _verdicts(
        exp.quick_protocol("methods"),
        lambda c, i: _metrics(
            error=cov[dict(c.settings)["method"]], cov=cov[dict(c.settings)["method"]] + 0.01 * i
        ),
    )
    assert verdicts == [True, True, True, True, True]


def test_methods_uncertainty_claim_fails_when_dqmpc_beats_active():
    cov = {"price": 2.0, "dqmpc": 0.4, "active": 0.5}
    verdicts = _verdicts(
        exp.quick_protocol("methods"), lambda c, i: _metrics(error=1.0, cov=cov[dict(c.settings)["method"]])
    )
    assert verdicts[0] is False


def test_uncertainty_evidence_counts_the_paired_runs_where_active_is_lower():
    cov = {
        ("price", 0): 2.0,
        ("price", 1): 2.0,
        ("dqmpc", 0): 1.0,
        ("dqmpc", 1): 0.2,
        ("active", 0): 0.5,
        ("active", 1): 0.5,
    }
    p = exp.quick_protocol("methods")
    results = _fake_results(p, lambda c, i: _metrics(error=1.0, cov=cov[(dict(c.settings)["method"], i)]))
    evidence = rep.check_claims(rep.summarize(p, results))[0].evidence
    assert "SE1 price 2.00 m^2 (SE3 active -75.0%, lower in 2 of 2 paired runs)" in evidence
    assert "SE2 dqmpc 0.600 m^2 (SE3 active -16.7%, lower in 1 of 2 paired runs)" in evidence


def test_se4_claim_shows_what_avoiding_obstacles_costs_against_se3():
    cov = {"none": 0.5, "paper": 0.7}
    p = exp.quick_protocol("methods")
    results = _fake_results(
        p, lambda c, i: _metrics(error=1.0, cov=cov[dict(c.settings)["virtual_obstacles"]])
    )
    evidence = rep.check_claims(rep.summarize(p, results))[1].evidence
    assert evidence.endswith(
        "what avoiding the obstacles costs SE4 against SE3: spacing_error_deg 7.00 vs "
        "5.00 deg, cov_trace_m2.mean 0.700 vs 0.500 m^2"
    )


def test_in_frame_claim_fails_below_90_percent():
    verdicts = _verdicts(exp.quick_protocol("methods"), lambda c, i: _metrics(error=1.0, in_frame=0.89))
    assert verdicts[2] is False


def test_scalability_claim_agrees_when_error_falls_with_team_size():
    p = exp.paper_protocol("scalability")
    assert _verdicts(p, lambda c, i: _metrics(error=2.0 / math.sqrt(c.x))) == [True]


def test_separation_notes_name_the_conditions_where_mavs_came_closer_than_d_min():
    p = exp.quick_protocol("scalability")

    def metrics_of(c, i):
        close = c.x == 16.0 and i == 1
        return {
            **_metrics(error=1.0),
            "min_separation_m": 0.9 if close else 2.5,
            "min_believed_separation_m": 2.1 if close else 3.0,
        }

    notes = rep.separation_notes(rep.summarize(p, _fake_results(p, metrics_of)))
    assert notes == [
        "16 MAVs: 1 of 2 runs, closest 0.900 m; "
        "the closest the MAVs believed themselves in those runs: 2.10 m"
    ]


def test_separation_notes_are_empty_when_every_run_kept_d_min():
    p = exp.quick_protocol("scalability")
    results = _fake_results(p, lambda c, i: {**_metrics(error=1.0), "min_separation_m": 1.5})
    assert rep.separation_notes(rep.summarize(p, results)) == []


def test_scalability_claim_fails_when_error_grows_with_team_size():
    p = exp.paper_protocol("scalability")
    assert _verdicts(p, lambda c, i: _metrics(error=0.1 * c.x)) == [False]


def test_commloss_claim_agrees_within_20_percent_at_25_percent_loss():
    p = exp.quick_protocol("commloss")
    assert _verdicts(p, lambda c, i: _metrics(error=1.0 + 0.0076 * c.x)) == [True, True]  # x=25: 1.19


def test_commloss_claim_fails_beyond_20_percent_at_25_percent_loss():
    p = exp.quick_protocol("commloss")
    assert _verdicts(p, lambda c, i: _metrics(error=1.0 + 0.0084 * c.x))[0] is False  # x=25: 1.21


def test_obstacles_claim_fails_when_the_error_doubles():
    p = exp.quick_protocol("obstacles")
    assert _verdicts(p, lambda c, i: _metrics(error=1.0 + c.x / 20.0)) == [False]


def test_claims_are_not_judged_when_their_conditions_were_not_run():
    p = exp.Protocol("commloss", exp.quick_protocol("commloss").conditions[2:], (10.0,))
    assert _verdicts(p, lambda c, i: _metrics(error=1.0)) == [None, None]


def test_failed_runs_are_counted_and_left_out_of_the_statistics():
    p = exp.quick_protocol("obstacles")
    results = _fake_results(p, lambda c, i: _metrics(error=1.0 + i))
    results[0] = exp.RunResult(spec=results[0].spec, report=None, error="RuntimeError: boom")
    s = rep.summarize(p, results)
    assert (s.conditions[0].runs_ok, s.conditions[0].runs_failed) == (1, 1)
    assert s.conditions[0].mean(rep.ERROR) == pytest.approx(2.0, abs=1e-12)


# ---- report and figures from hand-made runs ----------------------------------------------------------------


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_sweep_figure_is_a_png_of_the_configured_size(tmp_path):
    p = exp.quick_protocol("scalability")
    s = rep.summarize(p, _fake_results(p, lambda c, i: _metrics(error=1.0 / c.x + 0.01 * i)))
    path = figures.sweep_figure(s, tmp_path)
    w, h = _png_size(path)
    assert (w, h) == (
        round(figures.FIGURE_SIZE_IN[0] * figures.DPI),
        round(figures.FIGURE_SIZE_IN[1] * figures.DPI),
    )


def test_report_puts_one_table_and_the_claims_under_each_family(tmp_path):
    protocols = [exp.quick_protocol(f) for f in exp.FAMILIES]
    results = [r for p in protocols for r in _fake_results(p, lambda c, i: _metrics(error=1.0 + 0.1 * i))]
    summaries = [rep.summarize(p, results) for p in protocols]
    text = rep.render_report(
        context=rep.ReportContext("skyring experiment all", 0, "test"),
        summaries=summaries,
        results=results,
        figures=figures.draw_all(summaries, tmp_path),
        wall_time_s=1.0,
    )
    sections = rep.reproducible_part(text).split("\n## ")[1:]
    assert [s.split("\n")[0] for s in sections] == [rep.TITLES[f] for f in exp.FAMILIES]
    for section, protocol in zip(sections, protocols, strict=True):
        assert section.count("| metric |") == 1
        assert len(rep.check_claims(rep.summarize(protocol, results))) == section.count("\n- **")


# ---- progress bar ------------------------------------------------------------------------------------------


def test_progress_writes_one_line_per_finished_run_when_not_on_a_terminal():
    import io

    from server.cli.experiment import RunProgress

    specs = exp.plan_runs([exp.quick_protocol("obstacles")], base_seed=0)[:2]
    stream = io.StringIO()
    bar = RunProgress(total=2, stream=stream)
    bar(1, 2, exp.RunResult(spec=specs[0], report={"metrics": {}}))
    bar(2, 2, exp.RunResult(spec=specs[1], report=None, error="boom"))
    lines = stream.getvalue().splitlines()
    assert len(lines) == 2
    assert "1/2 runs, 0 failed" in lines[0] and lines[0].endswith("run 0 ok")
    assert "2/2 runs, 1 failed" in lines[1] and lines[1].endswith("run 1 FAILED")


# ---- acceptance: `skyring experiment all --quick` through the real command line ----------------------------
# Reproducibility is checked by running one family again with the same seed on one worker instead of two: a
# family's seeds do not depend on the other families (tested above), so its runs must come out identical,
# and rerunning all four families would double the cost of this module.

QUICK_SEED = 5


def _skyring(*args: str, out: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).with_name("skyring")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "server.cli"]
    return subprocess.run(
        [*command, "experiment", *args, "--seed", str(QUICK_SEED), "--out", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, "COLUMNS": "250"},  # error messages on one line
    )


@pytest.fixture(scope="module")
def quick_all(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """`skyring experiment all --quick --jobs 2`."""
    out = tmp_path_factory.mktemp("quick-all")
    return out, _skyring("all", "--quick", "--jobs", "2", out=out)


AGAIN = "obstacles"  # the family flown twice


@pytest.fixture(scope="module")
def quick_again(tmp_path_factory, quick_all) -> tuple[Path, subprocess.CompletedProcess]:
    """`skyring experiment obstacles --quick --jobs 1`: the obstacles family of `quick_all` once more, on one
    process (the smallest family: 4 runs of 5 MAVs)."""
    out = tmp_path_factory.mktemp("quick-again")
    return out, _skyring(AGAIN, "--quick", "--jobs", "1", out=out)


def _expected_figures() -> list[str]:
    names = [f"{stem}.png" for _, stem, _ in figures.METHOD_PANELS]
    return names + [f"{stem}.png" for stem, _ in figures.SWEEP_PANELS.values()]


def _section(report_md: str, family: str) -> str:
    """The report's section of `family`: from its heading to the next one."""
    body = report_md.split(f"\n## {rep.TITLES[family]}\n", 1)[1]
    return body.split("\n## ", 1)[0]


def _untimed_metrics(path: Path) -> dict:
    return {k: v for k, v in json.loads(path.read_text())["metrics"].items() if not rep.is_timing(k)}


def test_a_run_shorter_than_the_warm_up_is_refused_before_anything_runs(tmp_path, capsys):
    proc = run_skyring(capsys, "experiment", "methods", "--duration", "10", "--out", str(tmp_path))
    assert proc.returncode == 2
    assert "methods / SE1 price: warmup_s must be below duration_s (10 s), got 20" in proc.stderr
    assert not list(tmp_path.rglob("run-*.json"))


@pytest.mark.slow
def test_quick_experiment_succeeds_and_shows_progress(quick_all):
    out, proc = quick_all
    assert proc.returncode == 0, proc.stderr[-2000:]
    total = len(exp.plan_runs([exp.quick_protocol(f) for f in exp.FAMILIES], base_seed=QUICK_SEED))
    assert f"{total}/{total} runs, 0 failed" in proc.stderr


@pytest.mark.slow
def test_quick_experiment_draws_every_figure_as_a_png_of_sensible_size(quick_all):
    out, _ = quick_all
    for name in _expected_figures():
        w, h = _png_size(out / figures.FIGURES_DIR / name)
        assert 400 <= w <= 2000 and 300 <= h <= 1500, (name, w, h)
        assert (out / figures.FIGURES_DIR / name).stat().st_size > 10_000


@pytest.mark.slow
def test_quick_report_has_one_table_per_family_and_links_every_figure(quick_all):
    out, _ = quick_all
    body = rep.reproducible_part((out / "report.md").read_text())
    assert body.count("| metric |") == len(exp.FAMILIES)
    for family in exp.FAMILIES:
        assert _section(body, family).count("| metric |") == 1
    for name in _expected_figures():
        assert f"]({figures.FIGURES_DIR}/{name})" in body


@pytest.mark.slow
def test_quick_experiment_keeps_every_runs_json_under_its_family(quick_all):
    out, _ = quick_all
    specs = exp.plan_runs([exp.quick_protocol(f) for f in exp.FAMILIES], base_seed=QUICK_SEED)
    for spec in specs:
        doc = json.loads((out / spec.relative_path()).read_text())
        assert doc["experiment"]["seed"] == doc["config"]["seed"] == spec.seed
        assert "tracking_error_m" in doc["metrics"]


@pytest.mark.slow
def test_same_seed_reproduces_every_runs_metrics_on_any_number_of_workers(quick_all, quick_again):
    (first, _), (second, proc) = quick_all, quick_again
    assert proc.returncode == 0, proc.stderr[-2000:]
    files = sorted(p.relative_to(second) for p in second.rglob("run-*.json"))
    assert len(files) == len(exp.quick_protocol(AGAIN).conditions) * exp.QUICK_RUNS
    for rel in files:
        assert _untimed_metrics(first / rel) == _untimed_metrics(second / rel), rel


@pytest.mark.slow
def test_same_seed_reproduces_the_report_apart_from_timings(quick_all, quick_again):
    (first, _), (second, _) = quick_all, quick_again
    a = _section(rep.reproducible_part((first / "report.md").read_text()), AGAIN)
    b = _section(rep.reproducible_part((second / "report.md").read_text()), AGAIN)
    assert a == b


# ---- acceptance: the paper's orderings on a fixed-seed profile ---------------------------------------------
# The profile: SE1-SE3 with 5 MAVs (clustered start); 3 and 16 MAVs with the paper's trees; 0 % and 25 % link
# loss with 8 MAVs. Every condition: ORDERING_RUNS paired runs of ORDERING_DURATION_S (the first 20 s are the
# simulator's warm-up) at the MPC's own 10 Hz, base seed ORDERING_SEED.

ORDERING_RUNS = 3
ORDERING_DURATION_S = 45.0
ORDERING_RATE_HZ = 10.0
ORDERING_SEED = 2019


def _ordering_protocols() -> list[exp.Protocol]:
    def keep(family, wanted):
        p = exp.paper_protocol(family)
        p = exp.Protocol(family, tuple(c for c in p.conditions if c.x in wanted), p.durations_s, p.rate_hz)
        return exp.with_overrides(
            p,
            exp.ProfileOverrides(
                runs=ORDERING_RUNS, duration_s=ORDERING_DURATION_S, rate_hz=ORDERING_RATE_HZ
            ),
        )

    return [keep("methods", (1.0, 2.0, 3.0)), keep("scalability", (3.0, 16.0)), keep("commloss", (0.0, 25.0))]


@pytest.fixture(scope="module")
def ordering(tmp_path_factory) -> dict[str, rep.FamilySummary]:
    protocols = _ordering_protocols()
    specs = exp.plan_runs(protocols, base_seed=ORDERING_SEED)
    results = exp.run_all(specs, jobs=2, out_dir=tmp_path_factory.mktemp("ordering"))
    assert all(r.ok for r in results), [r.error for r in results if not r.ok]
    return {p.family: rep.summarize(p, results) for p in protocols}


def _mean(summary: rep.FamilySummary, metric: str, **settings) -> float:
    condition = summary.find(**settings)
    assert condition is not None, settings
    mean = condition.mean(metric)
    assert mean is not None, metric
    return mean


@pytest.mark.slow
def test_active_has_lower_mean_uncertainty_than_dqmpc_and_price(ordering):
    s = ordering["methods"]
    active = _mean(s, rep.UNCERTAINTY, method="active")
    assert active < _mean(s, rep.UNCERTAINTY, method="dqmpc")
    assert active < _mean(s, rep.UNCERTAINTY, method="price")


@pytest.mark.slow
def test_active_keeps_the_person_in_frame_at_least_90_percent_without_obstacles(ordering):
    assert _mean(ordering["methods"], rep.IN_FRAME, method="active", virtual_obstacles="none") >= 0.9


@pytest.mark.slow
def test_sixteen_mavs_track_the_person_more_accurately_than_three(ordering):
    s = ordering["scalability"]
    assert _mean(s, rep.ERROR, vehicles=16) < _mean(s, rep.ERROR, vehicles=3)


@pytest.mark.slow
def test_error_at_25_percent_link_loss_is_within_20_percent_of_the_lossless_error(ordering):
    s = ordering["commloss"]
    assert _mean(s, rep.ERROR, comm_loss=0.25) <= 1.2 * _mean(s, rep.ERROR, comm_loss=0.0)
