"""Sign-in, roles, Origin/Host checks, security headers and the audit trail of the ground station's HTTP
front, in-process (httpx over ASGI) and, for the WebSocket and TLS, over a real uvicorn on 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import ssl
import subprocess

import httpx
import pytest
import uvicorn
import websockets
from test_api import RATE_HZ, make_station
from websockets.typing import Origin

from server.station.api.app import create_app
from server.station.api.gate import SESSION_COOKIE, Gate
from server.station.api.routes_stream import handle_command
from server.station.api.users import Users, UsersError, hash_secret, user_line, verify_secret
from server.station.ground_station import GroundStation
from vehicles.sim.scenario import Scenario, build_sim
from webui.access import Principal, Role, Surface

OPERATOR, OBSERVER = ("alice", "alice-secret-1"), ("bob", "bob-secret-22")
MUTATING = [
    ("PUT", "/api/formation", {"d_des_m": 9.0, "h_des_m": 8.0}),
    ("POST", "/api/formation/start", None),
    ("POST", "/api/formation/start?override=true", None),
    ("POST", "/api/formation/stop", None),
    ("POST", "/api/obstacles", {"x_m": 15.0, "y_m": -15.0, "radius_m": 1.0}),
    ("DELETE", "/api/obstacles/t1", None),
    ("POST", "/api/vehicles/1/land", None),
    ("POST", "/api/vehicles/1/release", None),
    ("POST", "/api/vehicles/1/release?override=true", None),
    ("POST", "/api/land_all", None),
    ("POST", "/api/vehicles/1/hold", None),
    ("POST", "/api/alerts/a1/acknowledge", None),
    ("POST", "/api/alerts/acknowledge", None),
]


@pytest.fixture(scope="module")
def users() -> Users:
    text = "\n".join(
        [
            user_line(OPERATOR[0], Role.OPERATOR, OPERATOR[1]),
            user_line(OBSERVER[0], Role.OBSERVER, OBSERVER[1]),
        ]
    )
    return Users.parse(text, source="test")


@pytest.fixture
def station():
    """Three simulated MAVs a second into their take-off; MAV 1 at 20 % battery: alert a1, unacknowledged."""
    setup = build_sim(Scenario(vehicles=3, seed=3))
    s = GroundStation(mission=setup.mission, control_period_s=1.0 / RATE_HZ)
    setup.autopilots[0].set_battery(0.20)
    for _ in range(round(RATE_HZ)):
        s.tick()
    assert [(a.alert_id, a.kind, a.acknowledged) for a in s.alerts] == [("a1", "battery", False)]
    return s


def client(station, users, **kwargs) -> httpx.AsyncClient:
    app = create_app(station, viser_port=1, gate=Gate(users))
    return httpx.AsyncClient(
        transport=httpx.ASGITransport(app=app, client=("192.0.2.7", 5555)),
        base_url="http://127.0.0.1:8000",
        **kwargs,
    )


async def sign_in(c: httpx.AsyncClient, name: str, secret: str) -> str:
    response = await c.post("/auth/login", json={"name": name, "secret": secret})
    assert response.status_code == 200, response.text
    return response.json()["token"]


def digest(station) -> tuple:
    snap = station.snapshot()
    return (
        snap.formation,
        snap.formation_enabled,
        tuple(o.obstacle_id for o in snap.obstacles),
        tuple(v.phase for v in snap.vehicles),
        tuple((a.alert_id, a.acknowledged) for a in station.alerts),
    )


# ---- users and secrets


def test_a_secret_is_stored_as_an_scrypt_hash_that_verifies_only_itself():
    stored = hash_secret("correct horse")
    assert stored.startswith("scrypt$16384$8$1$") and "correct horse" not in stored
    assert verify_secret("correct horse", stored) and not verify_secret("correct hors", stored)


def test_a_users_file_with_a_plain_text_secret_or_a_bad_role_is_refused_naming_the_entry():
    with pytest.raises(UsersError, match="entry 1: the secret must be an scrypt hash"):
        Users.parse("alice operator hunter22", source="users.txt")
    with pytest.raises(UsersError, match="entry 2: role must be operator or observer"):
        Users.parse(f"# team\nbob admin {hash_secret('x' * 8)}", source="users.txt")


def test_a_user_never_shows_its_hash(users):
    user = users.check(*OPERATOR)
    assert user is not None and "scrypt" not in repr(user)


# ---- sign-in


async def test_sign_in_gives_a_token_and_an_http_only_same_site_strict_cookie(station, users):
    response = await client(station, users).post(
        "/auth/login", json={"name": OPERATOR[0], "secret": OPERATOR[1]}
    )
    assert response.status_code == 200 and response.json()["role"] == "operator"
    cookie = response.headers["set-cookie"]
    assert f"{SESSION_COOKIE}=" in cookie and "HttpOnly" in cookie and "SameSite=strict" in cookie
    assert OPERATOR[1] not in json.dumps([r.__dict__ for r in station.recent_audit])


async def test_a_wrong_secret_is_401_and_ten_of_them_lock_the_address_out(station, users):
    c = client(station, users)
    for _ in range(10):
        assert (
            await c.post("/auth/login", json={"name": "alice", "secret": "wrong-wrong"})
        ).status_code == 401
    assert (await c.post("/auth/login", json={"name": OPERATOR[0], "secret": OPERATOR[1]})).status_code == 429
    assert [r.accepted for r in station.recent_audit if r.command == "sign_in"] == [False] * 11


# ---- roles


@pytest.mark.parametrize(("method", "url", "body"), MUTATING)
async def test_without_sign_in_every_command_is_401_audited_and_changes_nothing(
    station, users, method, url, body
):
    before = digest(station)
    response = await client(station, users).request(method, url, json=body)
    assert response.status_code == 401, response.text
    assert digest(station) == before
    record = station.recent_audit[-1]
    assert (record.accepted, record.operator, record.role, record.surface) == (False, "", "", "api")
    assert record.remote == "192.0.2.7:5555" and record.command_id == response.headers["x-command-id"]


async def test_without_sign_in_the_state_and_the_operator_page_are_closed(station, users):
    c = client(station, users)
    assert (await c.get("/api/state")).status_code == 401
    page = await c.get("/operator/")
    assert page.status_code == 303 and page.headers["location"].startswith("/login")
    assert (await c.get("/")).headers["location"].startswith("/login")


@pytest.mark.parametrize(
    ("path", "location"),
    [
        ("/?fixedDpr=0.5", "/login?next=/%3FfixedDpr%3D0.5"),
        ("/operator/?fixedDpr=0.5", "/login?next=/operator/%3FfixedDpr%3D0.5"),
        ("/operator/?fixedDpr=0.5&next=//evil.example", "/login?next=/operator/%3FfixedDpr%3D0.5"),
        ("/?fixedDpr=1e9", "/login?next=/"),
        ("/?fixedDpr=nan", "/login?next=/"),
    ],
)
async def test_the_sign_in_redirect_keeps_a_valid_display_setting_and_nothing_else(
    station, users, path, location
):
    page = await client(station, users).get(path)
    assert (page.status_code, page.headers["location"]) == (303, location)


@pytest.mark.parametrize(("method", "url", "body"), MUTATING)
async def test_an_observer_watches_but_every_command_is_403_and_changes_nothing(
    station, users, method, url, body
):
    c = client(station, users)
    token = await sign_in(c, *OBSERVER)
    headers = {"authorization": f"Bearer {token}"}
    assert (await c.get("/api/state", headers=headers)).status_code == 200
    before = digest(station)
    response = await c.request(method, url, json=body, headers=headers)
    assert response.status_code == 403, response.text
    assert digest(station) == before
    record = station.recent_audit[-1]
    assert (record.accepted, record.operator, record.role) == (False, "bob", "observer")


async def test_an_operator_commands_and_the_audit_names_them(station, users):
    c = client(station, users)
    token = await sign_in(c, *OPERATOR)
    response = await c.post(
        "/api/land_all", headers={"authorization": f"Bearer {token}", "x-command-id": "op-42"}
    )
    assert response.status_code == 200 and response.json() == {"landing": [1, 2, 3]}
    record = station.recent_audit[-1]
    assert (
        record.command,
        record.operator,
        record.role,
        record.surface,
        record.command_id,
        record.accepted,
    ) == (
        "land_all",
        "alice",
        "operator",
        "api",
        "op-42",
        True,
    )


async def test_an_observers_override_is_refused_and_audited_with_the_override_asked_for(station, users):
    c = client(station, users)
    token = await sign_in(c, *OBSERVER)
    response = await c.post(
        "/api/vehicles/2/release", params={"override": "true"}, headers={"authorization": f"Bearer {token}"}
    )
    assert response.status_code == 403
    record = station.recent_audit[-1]
    assert (record.command, record.arguments, record.accepted) == (
        "release",
        {"vehicle_id": "2", "override": "true"},  # as sent: refused before they were parsed
        False,
    )


async def test_an_operators_override_is_an_audited_argument_of_the_command(station, users):
    c = client(station, users)
    token = await sign_in(c, *OPERATOR)
    headers = {"authorization": f"Bearer {token}"}
    response = await c.post("/api/formation/start", params={"override": "true"}, headers=headers)
    assert response.status_code == 200, response.text
    record = station.recent_audit[-1]
    assert (record.command, record.arguments, record.operator, record.accepted) == (
        "set_formation_enabled",
        {"enabled": True, "override": True},
        "alice",
        True,
    )
    await c.post("/api/formation/start", headers=headers)
    assert station.recent_audit[-1].arguments == {"enabled": True, "override": False}


def test_a_websocket_command_carries_its_override_into_the_audit(station):
    alice = Principal(name="alice", role=Role.OPERATOR, surface=Surface.WS, remote="192.0.2.7:5555")
    message = {"id": "w2", "command": "start_formation", "override": True}
    reply = handle_command(station, alice, json.dumps(message))
    assert reply["accepted"], reply
    record = station.recent_audit[-1]
    assert (record.command, record.arguments, record.surface, record.command_id) == (
        "set_formation_enabled",
        {"enabled": True, "override": True},
        "ws",
        "w2",
    )


def test_a_websocket_override_that_is_not_a_boolean_is_refused_as_malformed(station):
    alice = Principal(name="alice", role=Role.OPERATOR, surface=Surface.WS)
    before = digest(station)
    reply = handle_command(
        station, alice, json.dumps({"id": "w3", "command": "release", "vehicle_id": 1, "override": "yes"})
    )
    assert not reply["accepted"] and "override" in reply["detail"]
    assert digest(station) == before
    assert (station.recent_audit[-1].command, station.recent_audit[-1].accepted) == ("release", False)


async def test_an_operator_acknowledges_an_alert_and_holds_a_mav_and_the_audit_names_them(station, users):
    c = client(station, users)
    headers = {"authorization": f"Bearer {await sign_in(c, *OPERATOR)}"}
    response = await c.post("/api/alerts/a1/acknowledge", headers=headers)
    assert response.status_code == 200 and response.json()["acknowledged"] is True
    assert [(a.alert_id, a.acknowledged) for a in station.alerts] == [("a1", True)]
    for _ in range(round(3 * RATE_HZ)):  # airborne, then Hold stops it where it is
        station.tick()
    response = await c.post("/api/vehicles/2/hold", headers=headers)
    assert response.status_code == 200 and response.json()["phase"] == "holding"
    records = [(r.command, r.arguments, r.operator, r.surface, r.accepted) for r in station.recent_audit]
    assert records[-2:] == [
        ("acknowledge_alert", {"alert_id": "a1"}, "alice", "api", True),
        ("hold", {"vehicle_id": 2}, "alice", "api", True),
    ]


async def test_signing_out_ends_the_session(station, users):
    c = client(station, users)
    token = await sign_in(c, *OPERATOR)
    headers = {"authorization": f"Bearer {token}"}
    assert (await c.post("/auth/logout", headers=headers)).status_code == 204
    assert (await c.post("/api/land_all", headers=headers)).status_code == 401


# ---- origin, host, headers


@pytest.mark.parametrize(("method", "url", "body"), MUTATING)
async def test_a_command_from_a_foreign_origin_is_403_even_with_an_operator_cookie(
    station, users, method, url, body
):
    c = client(station, users)
    await sign_in(c, *OPERATOR)  # the cookie is now in the client's jar
    before = digest(station)
    response = await c.request(method, url, json=body, headers={"origin": "http://evil.example"})
    assert response.status_code == 403 and "another origin" in response.json()["detail"]
    assert digest(station) == before
    assert station.recent_audit[-1].operator == "alice" and not station.recent_audit[-1].accepted


async def test_the_station_without_sign_in_answers_only_to_loopback_host_names():
    c = httpx.AsyncClient(
        transport=httpx.ASGITransport(app=create_app(make_station(), viser_port=1)),
        base_url="http://127.0.0.1:8000",
    )
    assert (await c.get("/api/state")).status_code == 200
    assert (await c.get("/api/state", headers={"host": "rebound.example:8000"})).status_code == 400


@pytest.mark.parametrize("path", ["/", "/login", "/docs", "/api/state", "/operator/", "/openapi.json"])
async def test_every_page_carries_csp_frame_ancestors_and_nosniff(path):
    c = httpx.AsyncClient(
        transport=httpx.ASGITransport(app=create_app(make_station(), viser_port=1)),
        base_url="http://127.0.0.1:8000",
    )
    response = await c.get(path)
    assert response.status_code == 200
    assert "frame-ancestors 'self'" in response.headers["content-security-policy"]
    assert response.headers["x-content-type-options"] == "nosniff"
    assert response.headers["x-frame-options"] == "SAMEORIGIN"


# ---- over a real server: WebSocket, TLS


async def _serve(app, **ssl):
    server = uvicorn.Server(
        uvicorn.Config(
            app, host="127.0.0.1", port=0, log_level="warning", lifespan="off", ws="websockets-sansio", **ssl
        )
    )
    task = asyncio.create_task(server.serve())
    while not server.started:
        assert not task.done(), "uvicorn did not start"
        await asyncio.sleep(0.01)
    return server, task, server.servers[0].sockets[0].getsockname()[1]


async def test_the_websocket_refuses_anonymous_and_foreign_handshakes_and_observer_commands(station, users):
    app = create_app(station, viser_port=1, gate=Gate(users))
    server, task, port = await _serve(app)
    try:
        url = f"ws://127.0.0.1:{port}/ws"
        with pytest.raises(websockets.exceptions.InvalidStatus, match="403"):
            async with websockets.connect(url):
                pass
        async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as c:
            observer, operator = await sign_in(c, *OBSERVER), await sign_in(c, *OPERATOR)
        with pytest.raises(websockets.exceptions.InvalidStatus, match="403"):
            async with websockets.connect(
                url,
                additional_headers={"authorization": f"Bearer {operator}"},
                origin=Origin("http://evil.example"),
            ):
                pass
        before = digest(station)
        async with websockets.connect(url, additional_headers={"authorization": f"Bearer {observer}"}) as ws:
            await ws.send(json.dumps({"id": "w1", "command": "land_all"}))
            while "reply_to" not in (reply := json.loads(await ws.recv())):
                pass
        assert reply["reply_to"] == "w1" and not reply["accepted"] and "observer" in reply["detail"]
        assert digest(station) == before
        record = station.recent_audit[-1]
        assert (record.surface, record.operator, record.command_id, record.accepted) == (
            "ws",
            "bob",
            "w1",
            False,
        )
    finally:
        server.should_exit = True
        await task


async def test_tls_serves_https_with_a_secure_cookie_and_hsts(station, users, tmp_path):
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-nodes",
            "-days",
            "1",
            "-subj",
            "/CN=127.0.0.1",
            "-addext",
            "subjectAltName=IP:127.0.0.1",
            "-keyout",
            str(key),
            "-out",
            str(cert),
        ],
        check=True,
        capture_output=True,
    )
    app = create_app(station, viser_port=1, gate=Gate(users, secure=True))
    server, task, port = await _serve(app, ssl_certfile=str(cert), ssl_keyfile=str(key))
    try:
        async with httpx.AsyncClient(
            base_url=f"https://127.0.0.1:{port}", verify=ssl.create_default_context(cafile=str(cert))
        ) as c:
            response = await c.post("/auth/login", json={"name": OPERATOR[0], "secret": OPERATOR[1]})
            assert response.status_code == 200
            assert "Secure" in response.headers["set-cookie"]
            assert response.headers["strict-transport-security"].startswith("max-age=")
            assert (await c.get("/api/state")).status_code == 200  # the cookie rides over TLS
        with pytest.raises(httpx.HTTPError):
            async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{port}") as plain:
                await plain.get("/api/state")
    finally:
        server.should_exit = True
        await task
