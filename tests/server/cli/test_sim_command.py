"""`skyring sim`: arguments, the printed table, the JSON report, one-line errors."""

import json

import pytest
from cli_run import run_skyring

from server.cli.options import PersonMode, StartLayout
from vehicles.sim.person import PERSON_MODES
from vehicles.sim.scenario import START_LAYOUTS


def test_a_headless_run_prints_a_table_and_writes_the_report(tmp_path, capsys):
    path = tmp_path / "report.json"
    done = run_skyring(
        capsys,
        "sim",
        "--headless",
        "--vehicles",
        "2",
        "--duration",
        "12",
        "--warmup",
        "10",
        "--rate",
        "10",
        "--seed",
        "3",
        "--trees",
        "none",
        "--person",
        "still",
        "--report",
        str(path),
    )
    assert done.returncode == 0, done.stderr
    assert "tracking error" in done.stdout and "real-time factor" in done.stdout
    report = json.loads(path.read_text())
    assert set(report) == {"config", "metrics"}
    assert report["config"]["vehicles"] == 2 and report["config"]["trees"] == "none"
    assert report["config"]["rate_hz"] == 10.0 and report["config"]["seed"] == 3


@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--vehicles", "0"], "--vehicles"),
        (["--vehicles", "three"], "--vehicles"),
        (["--duration", "-5"], "--duration"),
        (["--comm-loss", "1.5"], "--comm-loss"),
        (["--comm-loss", "-0.1"], "--comm-loss"),
        (["--method", "magic"], "--method"),
        (["--trees", "forest"], "--trees"),
        (["--person", "dancing"], "--person"),
        (["--warmup", "90", "--duration", "60"], "--warmup"),
        (["--replan-rate", "500"], "--replan-rate"),
        (["--d-des", "nan"], "--d-des"),
        (["--start", "circle"], "--start"),
    ],
)
def test_a_bad_argument_exits_non_zero_with_one_line_naming_it(args, option, capsys):
    done = run_skyring(capsys, "sim", "--headless", *args)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert option in lines[0] and lines[0].startswith("Error: ")
    assert done.stdout == ""


def test_without_headless_it_points_to_skyring_serve(capsys):
    done = run_skyring(capsys, "sim")
    assert done.returncode == 2
    assert "skyring serve" in done.stderr and len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("command", ["sim", "serve"])
def test_both_commands_refuse_a_seventeenth_vehicle_in_one_line(command, capsys):
    done = run_skyring(
        capsys, command, "--vehicles", "17", *(["--headless"] if command == "sim" else ["--no-log"])
    )
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "Error: Invalid value for '--vehicles': Input should be less than or equal to 16"
    ]


def test_the_command_offers_exactly_the_people_and_start_layouts_the_scenario_knows():
    assert tuple(m.value for m in PersonMode) == PERSON_MODES
    assert tuple(s.value for s in StartLayout) == START_LAYOUTS
