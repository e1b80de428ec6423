"""The flight log of `skyring serve` and `skyring replay`: what a run records, that a crash or a failing disk
loses nothing else and never stops the MAVs, and the replay of a log (summary, playback, bad files)."""

from __future__ import annotations

import errno
import itertools
import json
import logging
import math
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import httpx
import pytest
from typer.testing import CliRunner

from server.cli import COMMANDS, _register, app
from server.cli.replay import serve_replay
from server.flightlog.log import FileSink, FlightLog, read_flight_log
from server.flightlog.records import (
    EstimateSample,
    LogHeader,
    LogSample,
    ObstacleSample,
    VehicleSample,
    scene_from,
)
from server.station.ground_station import GroundStation
from vehicles.sim.scenario import Scenario, build_sim

RATE_HZ = 20.0  # control rate of these tests; the log samples at 5 Hz of mission time
ROOT = Path(__file__).resolve().parents[3]
_register("replay", COMMANDS["replay"])
_register("serve", COMMANDS["serve"])


def header(**overrides: Any) -> LogHeader:
    fields: dict[str, Any] = dict(
        command="serve",
        vehicles=3,
        seed=3,
        method="active",
        trees="paper",
        person="paper",
        rate_hz=RATE_HZ,
        speed=1.0,
        sample_rate_hz=5.0,
        started_utc="2025-06-01T12:00:00+00:00",
    )
    fields.update(overrides)
    return LogHeader(**fields)


def make_station() -> GroundStation:
    setup = build_sim(Scenario(vehicles=3, seed=3))
    return GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)


def fly(station: GroundStation, ticks: int) -> None:
    for _ in range(ticks):
        station.tick()


def recorded_run(path: Path, *, ticks: int = 40, close: bool = True) -> FlightLog:
    """A station flown for `ticks` with a log at `path`: three commands (one refused), then closed or not."""
    station = make_station()
    flight_log = FlightLog.create(path, header=header())
    station.attach_log(flight_log)
    fly(station, ticks // 2)
    station.set_formation(d_des_m=7.0, h_des_m=8.0)
    with pytest.raises(ValueError, match="between 1.8 and 18.5 m"):
        station.set_formation(d_des_m=99.0, h_des_m=8.0)
    station.add_obstacle(x_m=-10.0, y_m=10.0, radius_m=1.0)
    fly(station, ticks - ticks // 2)
    if close:
        flight_log.close()
    return flight_log


class FailingSink:
    """A disk that fills up: the first `good` writes succeed, later ones raise ENOSPC (the first failing one
    after writing half its line, as a real short write would)."""

    def __init__(self, path: Path, *, good: int, recover_after: int | None = None) -> None:
        self.file = FileSink(path)
        self.good = good
        self.recover_after = recover_after
        self.writes = 0

    def write(self, data: bytes) -> None:
        self.writes += 1
        failing = self.writes > self.good and (
            self.recover_after is None or self.writes <= self.good + self.recover_after
        )
        if failing:
            if self.writes == self.good + 1:
                self.file.write(data[: len(data) // 2])
            raise OSError(errno.ENOSPC, "No space left on device")
        self.file.write(data)

    def sync(self) -> None:
        self.file.sync()

    def close(self) -> None:
        self.file.close()


def test_a_sample_reads_back_equal_to_what_was_written():
    sample = LogSample(
        time_s=12.35,
        d_des_m=8.0,
        h_des_m=6.5,
        formation_enabled=True,
        vehicles=(
            VehicleSample(
                vehicle_id=1,
                phase="formation",
                mode="offboard",
                armed=True,
                in_air=True,
                in_formation=True,
                position_m=(7.9, 0.1, 8.9),
                velocity_mps=(0.5, -0.25, 0.0),
                yaw_rad=-3.14159,
                link_age_s=0.02,
                link_stale=False,
                solve_status="solved",
                solver_time_s=0.0012,
                battery_fraction=0.87,
                plan_positions_m=((7.9, 0.1, 8.9), (7.95, 0.08, 8.9)),
            ),
            VehicleSample(
                vehicle_id=2,
                phase="landed",
                mode="hold",
                armed=False,
                in_air=False,
                in_formation=False,
                position_m=(-4.0, 6.9, 0.0),
                velocity_mps=(0.0, 0.0, 0.0),
                yaw_rad=0.0,
                link_age_s=math.inf,
                link_stale=True,
            ),
        ),
        obstacles=(
            ObstacleSample(
                obstacle_id="tree-1", kind="tree", center_m=(-14.0, -7.0), radius_m=0.5, height_m=10.0
            ),
            ObstacleSample(
                obstacle_id="v1", kind="virtual", center_m=(-10.0, 10.0), radius_m=1.0, height_m=12.0
            ),
        ),
        person_truth_m=(0.1, 0.2, 0.9),
        estimate=EstimateSample(
            source_id=1,
            stamp_s=12.34,
            position_m=(0.12, 0.18, 0.91),
            velocity_mps=(1.0, 0.0, 0.0),
            cov=tuple(float(i) / 100 for i in range(36)),
        ),
        tracking_error_m=0.03,
        d_des_range_m=(1.8, 18.5),
        h_des_range_m=(2.1, 9.1),
        camera=(0.707537, 1.87845, 0.785398, 0.18),
    )
    line = json.dumps(sample.to_json(), allow_nan=False)  # strict JSON: the never-heard-from link age is null
    assert LogSample.from_json(json.loads(line)) == sample
    assert json.loads(line)["vehicles"][1]["link_age_s"] is None


def test_a_station_run_records_the_header_samples_at_5_hz_and_every_command(tmp_path):
    path = tmp_path / "flight.jsonl"
    recorded_run(path, ticks=40)  # 2.0 s of mission time at 20 Hz
    record = read_flight_log(path)
    assert record.header == header()
    assert [round(s.time_s, 6) for s in record.samples] == [
        0.0,
        0.2,
        0.4,
        0.6,
        0.8,
        1.0,
        1.2,
        1.4,
        1.6,
        1.8,
        2.0,
    ]
    assert [len(s.vehicles) for s in record.samples] == [3] * 11
    assert record.samples[-1].d_des_m == 7.0
    assert [o.obstacle_id for o in record.samples[-1].obstacles if o.kind == "virtual"] == ["v1"]
    names = [(c.name, c.accepted, c.result) for c in record.commands]
    assert names == [
        ("set_formation", True, None),
        ("set_formation", False, None),
        ("add_obstacle", True, "v1"),
    ]
    refused = record.commands[1]
    assert refused.arguments == (("d_des_m", 99.0), ("h_des_m", 8.0))
    assert "choose a value between 1.8 and 18.5 m" in refused.message
    assert round(refused.time_s, 6) == 1.0
    assert record.end is not None and record.end.samples == 11 and record.end.commands == 3
    assert record.truncated_lines == 0


def test_a_log_cut_mid_line_by_a_crash_keeps_every_complete_line_and_counts_one_truncated(tmp_path):
    path = tmp_path / "flight.jsonl"
    recorded_run(path, ticks=40, close=False)  # the ground station "crashed": no end record
    data = path.read_bytes()
    last_start = data.rstrip(b"\n").rfind(b"\n") + 1
    crashed = tmp_path / "crashed.jsonl"
    crashed.write_bytes(data[: last_start + (len(data) - last_start) // 2])
    whole, cut = read_flight_log(path), read_flight_log(crashed)
    assert (len(whole.samples), whole.truncated_lines, whole.end) == (11, 0, None)
    assert (len(cut.samples), len(cut.commands), cut.truncated_lines, cut.end) == (10, 3, 1, None)
    assert cut.samples == whole.samples[:10]


def test_a_failing_log_never_breaks_a_tick_or_a_command_and_counts_each_lost_record(tmp_path, caplog):
    station = make_station()
    flight_log = FlightLog(sink=FailingSink(tmp_path / "full.jsonl", good=1), header=header())  # header only
    station.attach_log(flight_log)
    with caplog.at_level(logging.ERROR, logger="server.flightlog.log"):
        fly(station, 40)
        station.set_formation(d_des_m=7.0, h_des_m=8.0)
    assert round(station.time_s, 6) == 2.0
    assert station.snapshot().formation.d_des_m == 7.0
    assert (flight_log.samples, flight_log.commands, flight_log.write_errors) == (0, 0, 12)
    assert len([r for r in caplog.records if "No space left" in r.getMessage()]) == 1


def test_after_a_failed_write_the_next_record_starts_on_a_fresh_line(tmp_path):
    path = tmp_path / "flight.jsonl"
    station = make_station()
    # header and the first sample written, the second sample cut short, the disk back for the rest
    flight_log = FlightLog(sink=FailingSink(path, good=2, recover_after=1), header=header())
    station.attach_log(flight_log)
    fly(station, 40)
    flight_log.close()
    record = read_flight_log(path)
    assert (len(record.samples), record.truncated_lines, flight_log.write_errors) == (10, 1, 1)
    assert record.end is not None and record.end.write_errors == 1


class CountingSink:
    def __init__(self) -> None:
        self.lines: list[bytes] = []
        self.syncs = 0

    def write(self, data: bytes) -> None:
        self.lines.append(data)

    def sync(self) -> None:
        self.syncs += 1

    def close(self) -> None:
        pass


def test_the_log_is_fsynced_at_most_once_a_second_and_on_close():
    sink, wall = CountingSink(), [0.0]
    flight_log = FlightLog(sink=sink, header=header(), clock=lambda: wall[0])
    for _ in range(25):  # 25 records over 2.5 s of wall time
        wall[0] += 0.1
        flight_log.record_sample(
            lambda: LogSample(
                time_s=wall[0], vehicles=(), obstacles=(), d_des_m=8.0, h_des_m=8.0, formation_enabled=True
            )
        )
    assert (len(sink.lines), sink.syncs) == (26, 2)
    flight_log.close()
    assert (len(sink.lines), sink.syncs) == (27, 3)


def test_replay_summary_prints_duration_vehicles_commands_separation_and_truncated_lines(tmp_path):
    path = tmp_path / "flight.jsonl"
    recorded_run(path, ticks=40)
    samples = read_flight_log(path).samples
    closest = min(
        math.dist(a.position_m, b.position_m)
        for s in samples
        for a, b in itertools.combinations([v for v in s.vehicles if v.in_air], 2)
    )
    result = CliRunner().invoke(app, ["replay", str(path), "--summary"])
    assert result.exit_code == 0, result.output
    assert "duration         2.0 s (11 samples at 5 Hz)" in result.output
    assert "vehicles         3 (1, 2, 3)" in result.output
    assert "commands         2 accepted, 1 refused" in result.output
    assert f"min separation   {closest:.2f} m between airborne MAVs" in result.output
    assert "truncated lines  0" in result.output
    assert "ended            cleanly" in result.output


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (None, "cannot read the flight log"),
        (b"hello, world\n", "the first line is not JSON"),
        (
            b'{"kind": "header", "format": "skyring-flight-log", "version": 99}\n',
            "version 99 is not supported",
        ),
        (b'{"config": {}, "metrics": {}}\n', "not a skyring flight-log header"),
    ],
)
def test_replay_of_a_bad_file_exits_non_zero_with_one_line_naming_it(tmp_path, content, reason):
    path = tmp_path / "bad.jsonl"
    if content is not None:
        path.write_bytes(content)
    result = CliRunner().invoke(app, ["replay", str(path), "--summary"])
    assert result.exit_code == 1
    assert result.stderr.count("\n") == 1
    assert str(path) in result.stderr and reason in result.stderr


def test_replay_draws_the_recorded_samples_in_the_operator_scene(tmp_path):
    path = tmp_path / "flight.jsonl"
    recorded_run(path, ticks=40)
    record = read_flight_log(path)
    stop, ended, ready = threading.Event(), threading.Event(), {}
    thread = threading.Thread(
        target=lambda: ready.setdefault(
            "published",
            serve_replay(
                record,
                viser_port=0,
                speed=100.0,
                stop=stop,
                on_ready=lambda url, ui: ready.update(url=url, ui=ui),
                on_end=ended.set,
            ),
        )
    )
    thread.start()
    try:
        assert ended.wait(timeout=60)
        assert httpx.get(ready["url"], timeout=10).status_code == 200
        scene = ready["ui"].server.scene
        last = scene_from(record.samples[-1])
        for vehicle in last.vehicles:
            assert scene.get_handle_by_name(f"/mav/{vehicle.vehicle_id}").position == pytest.approx(
                vehicle.position_m
            )
        assert scene.get_handle_by_name("/obstacle/v1") is not None
        with pytest.raises(ValueError, match="replay"):
            ready["ui"].panel._actions.land_all()
    finally:
        stop.set()
        thread.join(timeout=30)
    assert ready["published"] == 11


def test_serve_with_and_without_log_is_refused():
    result = CliRunner().invoke(app, ["serve", "--log", "x.jsonl", "--no-log"])
    assert result.exit_code == 2
    assert "--log PATH or --no-log, not both" in result.output


@pytest.mark.e2e  # starts `skyring serve` as a process
def test_serve_writes_its_flight_log_where_asked_and_prints_the_path(tmp_path):
    path = tmp_path / "serve.jsonl"
    command = [
        sys.executable,
        "-m",
        "server.cli",
        "serve",
        "--port",
        "0",
        "--viser-port",
        "0",
        "--speed",
        "4",
        "--rate",
        "20",
        "--log",
        str(path),
    ]
    proc = subprocess.Popen(
        command,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        seen = ""
        assert proc.stdout is not None
        for line in proc.stdout:
            seen += line
            if line.startswith("Ctrl-C"):
                break
        assert f"flight log:     {path}" in seen, seen
        with path.open() as f:  # samples arrive while it flies
            while sum(1 for line in f if '"kind":"sample"' in line) < 3:
                f.seek(0)
                threading.Event().wait(0.2)
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    record = read_flight_log(path)
    assert record.header.command == "serve" and record.header.rate_hz == 20.0
    assert record.end is not None and [c.name for c in record.commands] == ["shutdown"]
    summary = rf"flight log:\s+{re.escape(str(path))} \({len(record.samples)} samples, 1 commands\)"
    assert re.search(summary, out), out
