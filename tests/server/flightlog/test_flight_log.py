"""The flight log of `skyring serve` and `skyring replay`: an MCAP file that the `mcap` reader and Foxglove
open (scene channels on Foxglove schemas), that records who sent every command, that a kill -9 cuts at most
the last second off and that stays readable, and its replay (summary, audit, playback, bad files)."""

from __future__ import annotations

import itertools
import math
import signal
import subprocess
import threading
import time
from pathlib import Path

import httpx
import pytest
from log_headers import log_header
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from serve_process import start_serve
from typer.testing import CliRunner

from server.cli import COMMANDS, _register, app
from server.cli.replay import serve_replay
from server.flightlog.channels import AUDIT_TOPIC, SCENE_TOPIC, STATE_TOPIC
from server.flightlog.log import FlightLog
from server.flightlog.reader import read_flight_log
from server.station.ground_station import GroundStation
from vehicles.sim.scenario import Scenario, build_sim
from webui.access import Principal, Role, Surface, acting_as

RATE_HZ = 20.0  # control rate of these tests; the log samples at 5 Hz of mission time
_register("replay", COMMANDS["replay"])
_register("serve", COMMANDS["serve"])
ALICE = Principal(name="alice", role=Role.OPERATOR, surface=Surface.API, remote="192.0.2.7:5555")


def make_station() -> GroundStation:
    setup = build_sim(Scenario(vehicles=3, seed=3))
    return GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)


def fly(station: GroundStation, ticks: int) -> None:
    for _ in range(ticks):
        station.tick()


def recorded_run(path: Path, *, ticks: int = 40, close: bool = True) -> FlightLog:
    """A station flown for `ticks` with a log at `path`: three commands by alice (one refused), then closed
    or not."""
    station = make_station()
    flight_log = FlightLog.create(path, header=log_header())
    station.attach_log(flight_log)
    fly(station, ticks // 2)
    with acting_as(ALICE.for_command("c1")):
        station.set_formation(d_des_m=7.0, h_des_m=8.0)
    with acting_as(ALICE.for_command("c2")), pytest.raises(ValueError, match="between 1.8 and 18.5 m"):
        station.set_formation(d_des_m=99.0, h_des_m=8.0)
    with acting_as(ALICE.for_command("c3")):
        station.add_obstacle(x_m=-10.0, y_m=10.0, radius_m=1.0)
    fly(station, ticks - ticks // 2)
    if close:
        flight_log.close()
    return flight_log


def test_a_station_run_records_the_header_samples_at_5_hz_and_every_command_with_who_sent_it(tmp_path):
    path = tmp_path / "flight.mcap"
    recorded_run(path, ticks=40)  # 2.0 s of mission time at 20 Hz
    record = read_flight_log(path)
    assert record.header == log_header()
    assert [round(s.time_s, 6) for s in record.samples] == pytest.approx([0.2 * k for k in range(11)])
    assert [len(s.vehicles) for s in record.samples] == [3] * 11
    assert record.samples[-1].formation.d_des_m == 7.0
    assert [o.obstacle_id for o in record.samples[-1].obstacles if o.kind == "virtual"] == ["v1"]
    rows = [(a.command, a.command_id, a.accepted, a.result) for a in record.audit]
    assert rows == [
        ("set_formation", "c1", True, None),
        ("set_formation", "c2", False, None),
        ("add_obstacle", "c3", True, "v1"),
    ]
    refused = record.audit[1]
    assert (refused.operator, refused.role, refused.surface, refused.remote) == (
        "alice",
        "operator",
        "api",
        "192.0.2.7:5555",
    )
    assert refused.arguments == {"d_des_m": 99.0, "h_des_m": 8.0}
    assert "choose a value between 1.8 and 18.5 m" in refused.message
    assert round(refused.time_s, 6) == 1.0
    assert record.end is not None and (record.end.samples, record.end.audit_records) == (11, 3)
    assert not record.truncated and record.bad_messages == 0


def test_the_log_opens_in_the_mcap_reader_with_the_scene_on_foxglove_schemas_in_the_world_frame(tmp_path):
    path = tmp_path / "flight.mcap"
    recorded_run(path, ticks=300)  # 15 s: the team flies and tracks the person
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        assert (schemas[SCENE_TOPIC].name, schemas[SCENE_TOPIC].encoding) == (
            "foxglove.SceneUpdate",
            "protobuf",
        )
        assert schemas[STATE_TOPIC].encoding == "jsonschema" and schemas[AUDIT_TOPIC].encoding == "jsonschema"
        updates = [m for _, c, _, m in reader.iter_decoded_messages(topics=[SCENE_TOPIC])]
    assert len(updates) == 76
    last = {e.id: e for e in updates[-1].entities}
    assert {
        "mav/1",
        "mav/2",
        "mav/3",
        "person/truth",
        "person/estimate",
        "person/covariance",
        "formation/circle",
        "obstacle/v1",
    } <= set(last)
    assert {e.frame_id for e in last.values()} == {"world"}
    assert any(k.startswith("plan/") for k in last)
    assert len(last["mav/1"].cubes) == 1 and len(last["mav/1"].lines[0].points) == 16  # body and frustum
    assert last["obstacle/v1"].cylinders[0].size.x == pytest.approx(2.0)


def test_a_log_cut_anywhere_reads_up_to_the_cut_and_says_so(tmp_path):
    path = tmp_path / "flight.mcap"
    recorded_run(path, ticks=40, close=False)  # no end record, no summary: as after a crash
    data = path.read_bytes()
    whole = read_flight_log(path)
    assert whole.end is None and len(whole.samples) == 11
    for fraction in (0.3, 0.6, 0.9, 0.999):
        cut = tmp_path / f"cut-{fraction}.mcap"
        cut.write_bytes(data[: int(len(data) * fraction)])
        record = read_flight_log(cut)
        assert record.truncated and record.end is None
        assert [s.time_s for s in record.samples] == [s.time_s for s in whole.samples[: len(record.samples)]]


def test_replay_summary_and_audit_print_what_happened_and_who_did_it(tmp_path):
    path = tmp_path / "flight.mcap"
    recorded_run(path, ticks=40)
    samples = read_flight_log(path).samples
    closest = min(
        math.dist(a.position_m, b.position_m)
        for s in samples
        for a, b in itertools.combinations([v for v in s.vehicles if v.in_air], 2)
    )
    result = CliRunner().invoke(app, ["replay", str(path), "--summary", "--audit"])
    assert result.exit_code == 0, result.output
    assert "duration         2.0 s (11 samples at 5 Hz)" in result.output
    assert "commands         2 accepted, 1 refused" in result.output
    assert f"min separation   {closest:.2f} m between airborne MAVs" in result.output
    assert "ended            cleanly" in result.output
    audit = [
        line for line in result.output.splitlines() if "alice [operator] via api from 192.0.2.7:5555" in line
    ]
    assert len(audit) == 3 and "c2" in audit[1] and "REFUSED: d_des_m = 99 m" in audit[1]


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (None, "cannot read the flight log"),
        (b"hello, world\n", "not an MCAP file"),
        (b'{"kind": "header"}\n', "not an MCAP file"),
    ],
)
def test_replay_of_a_bad_file_exits_non_zero_with_one_line_naming_it(tmp_path, content, reason):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    result = CliRunner().invoke(app, ["replay", str(path), "--summary"])
    assert result.exit_code == 1
    assert result.stderr.count("\n") == 1
    assert str(path) in result.stderr and reason in result.stderr


def test_replay_draws_the_recorded_samples_in_the_operator_scene(tmp_path):
    path = tmp_path / "flight.mcap"
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
        for vehicle in record.samples[-1].vehicles:
            drawn = scene.get_handle_by_name(f"/mav/{vehicle.vehicle_id}").position
            assert drawn == pytest.approx(vehicle.position_m)
        assert scene.get_handle_by_name("/obstacle/v1") is not None
        with pytest.raises(ValueError, match="replay"):
            ready["ui"].panel._actions.land_all()
    finally:
        stop.set()
        thread.join(timeout=30)
    assert ready["published"] == 11


def test_serve_with_and_without_log_is_refused():
    result = CliRunner().invoke(app, ["serve", "--log", "x.mcap", "--no-log"])
    assert result.exit_code == 2
    assert "--log PATH or --no-log, not both" in result.output


def _start_serve(path: Path, *extra: str) -> tuple[subprocess.Popen, str]:
    return start_serve("--log", str(path), *extra)


@pytest.mark.slow
@pytest.mark.e2e  # starts `skyring serve` as a process
def test_a_kill_9_loses_at_most_the_last_second_and_the_cut_log_replays(tmp_path):
    path = tmp_path / "killed.mcap"
    proc, api = _start_serve(path)
    try:
        time.sleep(4.0)
        landed = httpx.post(f"{api}api/land_all", headers={"x-command-id": "before-kill"}, timeout=10)
        assert landed.status_code == 200
        time.sleep(2.0)
        t_kill = httpx.get(f"{api}api/state", timeout=10).json()["time_s"]
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    record = read_flight_log(path)
    assert record.end is None
    lost_s = t_kill - record.samples[-1].time_s
    print(f"kill -9 lost the last {lost_s:.2f} s of mission time")
    assert lost_s <= 1.0  # one flush period (0.75 s) plus one sample period (0.2 s)
    assert [a.command_id for a in record.audit] == ["before-kill"]
    result = CliRunner().invoke(app, ["replay", str(path), "--summary"])
    assert result.exit_code == 0 and "without an end record" in result.output


@pytest.mark.e2e  # starts `skyring serve` as a process
def test_serve_writes_its_flight_log_where_asked_and_prints_the_path(tmp_path):
    path = tmp_path / "serve.mcap"
    proc, _ = _start_serve(path, "--speed", "4")
    try:
        deadline = time.monotonic() + 60
        while len(read_flight_log(path).samples) < 3:  # samples reach the file while it flies
            assert time.monotonic() < deadline
            time.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    record = read_flight_log(path)
    assert record.header.command == "serve" and record.header.rate_hz == 20.0
    assert record.end is not None and [a.command for a in record.audit] == ["shutdown"]
    assert f"flight log:     {path} ({len(record.samples)} samples, 1 audit records)" in out
