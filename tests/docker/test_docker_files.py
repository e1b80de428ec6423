"""docker/: the compose file, the two images and their entry points, checked without a Docker engine.

The compose file is parsed and its services, images, builds, ports and volumes cross-checked; the Dockerfiles
are read instruction by instruction (stages, pinned PX4 tag and commit, files copied exist); both entry points
run under `sh` against stand-ins for `skyring` and for PX4 (a copy of PX4 v1.16.0's MAVLink startup lines),
so what they would start in a container is checked here.
"""

from __future__ import annotations

import os
import re
import stat
import subprocess
from pathlib import Path

import pytest
import yaml

from server.station.px4 import px4_urls

DOCKER = Path(__file__).resolve().parents[2] / "docker"
PX4_TAG = "v1.16.0"
PX4_COMMIT = "6ea3539157ca358c70a515878b77077af7d4611d"  # git rev-parse v1.16.0 in PX4-Autopilot

# PX4 v1.16.0's etc/init.d-posix/px4-rc.mavlink, its `mavlink start` lines (the ones the entry point edits).
PX4_RC_MAVLINK = """#!/bin/sh
udp_offboard_port_local=$((14580+px4_instance))
udp_offboard_port_remote=$((14540+px4_instance))
udp_gcs_port_local=$((18570+px4_instance))
mavlink start -x -u $udp_gcs_port_local -r 4000000 -f
mavlink start -x -u $udp_offboard_port_local -r 4000000 -f -m onboard -o $udp_offboard_port_remote
mavlink start -x -u $udp_onboard_payload_port_local -r 4000 -f -m onboard -o $udp_onboard_payload_port_remote
"""


def compose() -> dict:
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())


def instructions(dockerfile: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined, comments dropped."""
    text = re.sub(r"\\\n", " ", (DOCKER / dockerfile).read_text())
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            keyword, _, rest = line.partition(" ")
            out.append((keyword.upper(), rest.strip()))
    return out


def px4_services(spec: dict) -> dict[str, dict]:
    return {name: s for name, s in spec["services"].items() if name.startswith("px4-")}


def test_px4_services_build_px4_v1_16_0_from_its_tag_not_a_missing_image():
    for name, service in px4_services(compose()).items():
        assert service["build"] == {
            "context": ".",
            "dockerfile": "px4-sitl.Dockerfile",
            "args": {"PX4_TAG": PX4_TAG},
        }
        assert service["image"] == f"skyring-px4-sitl:{PX4_TAG}", name
        assert "px4io/px4-sitl" not in str(service)  # published only from v1.17 on


def test_px4_image_clones_the_pinned_tag_and_checks_its_commit():
    steps = instructions("px4-sitl.Dockerfile")
    args = dict(a.split("=", 1) for k, a in steps if k == "ARG" and "=" in a)
    assert args == {"PX4_TAG": PX4_TAG, "PX4_COMMIT": PX4_COMMIT}
    runs = " ".join(a for k, a in steps if k == "RUN")
    assert 'git clone --depth 1 --branch "$PX4_TAG" https://github.com/PX4/PX4-Autopilot.git' in runs
    assert 'test "$(git -C /src/PX4 rev-parse HEAD)" = "$PX4_COMMIT"' in runs
    for submodule in (
        "src/modules/mavlink/mavlink",
        "src/drivers/gps/devices",
        "src/lib/events/libevents",
        "src/lib/heatshrink/heatshrink",
    ):
        assert submodule in runs
    assert "CONFIG_MODULES_GYRO_FFT CONFIG_MODULES_UXRCE_DDS_CLIENT" in runs
    assert "empy==3.3.4" in runs
    assert "-DCONFIG=px4_sitl_default" in runs


def test_px4_image_stages_copy_what_exists():
    steps = instructions("px4-sitl.Dockerfile")
    stages = [a.split(" AS ")[-1] for k, a in steps if k == "FROM" and " AS " in a]
    assert stages == ["build"]
    assert [a for k, a in steps if k == "FROM"][-1] == "debian:bookworm-slim"
    for keyword, arguments in steps:
        if keyword == "COPY" and "--from=" not in arguments:
            source = arguments.split()[-2]
            assert (DOCKER / source).exists(), source  # build context: docker/
        elif keyword == "COPY":
            assert "--from=build /src/PX4/build/px4_sitl_default/" in arguments
    env = " ".join(a for k, a in steps if k == "ENV")
    assert "PX4_SIM_MODEL=sihsim_quadx" in env and "PX4_SYS_AUTOSTART=10040" in env
    assert ("ENTRYPOINT", '["/usr/local/bin/px4-sitl-entrypoint.sh"]') in steps


def test_ground_station_listens_where_each_px4_instance_sends():
    spec = compose()
    ground = spec["services"]["groundstation"]
    k = int(ground["environment"]["SKYRING_PX4_SITL"])
    instances = sorted(int(s["environment"]["PX4_INSTANCE"]) for s in px4_services(spec).values())
    assert instances == list(range(k))
    for service in px4_services(spec).values():
        env = service["environment"]
        assert env["SKYRING_GCS_HOST"] == "groundstation"
        assert {"PX4_HOME_LAT", "PX4_HOME_LON", "PX4_HOME_ALT"} <= set(env)
        assert service["depends_on"] == ["groundstation"]
    assert ground["build"] == {"context": "..", "dockerfile": "docker/Dockerfile"}
    assert "flight-logs" in spec["volumes"]


def test_spawn_points_stand_outside_the_persons_keep_out_and_apart():
    import math

    lat0, lon0, _ = (
        float(x) for x in compose()["services"]["groundstation"]["environment"]["SKYRING_ORIGIN"].split(",")
    )
    points = []
    for service in px4_services(compose()).values():
        env = service["environment"]
        north = (float(env["PX4_HOME_LAT"]) - lat0) * 111_195.0
        east = (float(env["PX4_HOME_LON"]) - lon0) * 111_195.0 * math.cos(math.radians(lat0))
        points.append((east, north))
    for e, n in points:
        assert math.hypot(e, n) > 7.0  # the keep-out at the default d_des of 8 m
    assert min(math.dist(a, b) for i, a in enumerate(points) for b in points[i + 1 :]) > 1.5


def executable(path: Path) -> bool:
    return bool(path.stat().st_mode & stat.S_IXUSR)


@pytest.mark.parametrize("script", ["px4-sitl-entrypoint.sh", "groundstation-entrypoint.sh"])
def test_entry_points_are_valid_sh_and_executable(script):
    path = DOCKER / script
    assert (
        executable(path)
        or "--chmod=755" in (DOCKER / "px4-sitl.Dockerfile").read_text() + (DOCKER / "Dockerfile").read_text()
    )
    subprocess.run(["sh", "-n", str(path)], check=True)


def test_px4_entry_point_points_every_mavlink_link_at_the_ground_station_and_starts_px4(tmp_path):
    prefix = tmp_path / "px4"
    (prefix / "etc" / "init.d-posix").mkdir(parents=True)
    (prefix / "bin").mkdir()
    rc = prefix / "etc" / "init.d-posix" / "px4-rc.mavlink"
    rc.write_text(PX4_RC_MAVLINK)
    fake_px4 = prefix / "bin" / "px4"
    fake_px4.write_text('#!/bin/sh\necho "px4 $*"\n')
    fake_px4.chmod(0o755)
    env = {
        **os.environ,
        "PX4_PREFIX": str(prefix),
        "PX4_WORK": str(tmp_path / "work"),
        "PX4_INSTANCE": "2",
        "SKYRING_GCS_HOST": "localhost",
    }
    out = subprocess.run(
        ["sh", str(DOCKER / "px4-sitl-entrypoint.sh")], env=env, capture_output=True, text=True, check=True
    ).stdout
    assert f"px4 -d {prefix}/etc -i 2 -w {tmp_path}/work/2" in out
    edited = rc.read_text()
    starts = [line for line in edited.splitlines() if line.startswith("mavlink start")]
    assert len(starts) == 3 and all(line.startswith("mavlink start -x -t 127.0.0.1 -u ") for line in starts)
    # running it again (a container restart) replaces the target instead of adding one
    subprocess.run(["sh", str(DOCKER / "px4-sitl-entrypoint.sh")], env=env, capture_output=True, check=True)
    assert rc.read_text() == edited


def test_ground_station_entry_point_turns_the_team_size_into_skyrings_px4_urls(tmp_path):
    fake = tmp_path / "skyring"
    fake.write_text('#!/bin/sh\necho "skyring $*"\n')
    fake.chmod(0o755)
    env = {
        **os.environ,
        "PATH": f"{tmp_path}:{os.environ['PATH']}",
        "SKYRING_PX4_SITL": "3",
        "SKYRING_ORIGIN": "47.397742,8.545594,488.0",
    }
    command = compose()["services"]["groundstation"]["command"]
    out = subprocess.run(
        ["sh", str(DOCKER / "groundstation-entrypoint.sh"), *command],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    assert out[:3] == ["skyring", "serve", "--px4"]
    assert out[3].split(",") == px4_urls(sitl=3)
    assert out[4:6] == ["--origin", "47.397742,8.545594,488.0"]
    assert out[6:] == command[1:]


def test_ground_station_build_context_lets_through_everything_its_image_copies():
    ignore = [line for line in (DOCKER / "Dockerfile.dockerignore").read_text().splitlines() if line]
    assert "*" in ignore  # everything else stays out
    for keyword, arguments in instructions("Dockerfile"):
        if keyword != "COPY":
            continue
        sources = [a for a in arguments.split() if not a.startswith("--")][:-1]
        for source in sources:
            assert (DOCKER.parent / source).exists(), source
            assert f"!{source.rstrip('/')}/" in ignore or f"!{source}" in ignore, source
