"""schemathesis, a real API fuzzer, against the station's app over a real simulated mission: for every
operation of the OpenAPI document, generated valid and invalid requests never get a server error, every
response matches the schema (status, headers, body), and a refused request changes nothing."""

from __future__ import annotations

import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.specs.openapi.checks import positive_data_acceptance

from server.station.api.app import create_app
from server.station.ground_station import GroundStation
from vehicles.sim.scenario import Scenario, build_sim

EXAMPLES = 100  # per operation
ALL_HEALTH_CHECKS = [  # the requests are slow-ish and filtered by design; none of these says the API is wrong
    HealthCheck.data_too_large,
    HealthCheck.filter_too_much,
    HealthCheck.too_slow,
    HealthCheck.large_base_example,
    HealthCheck.function_scoped_fixture,
    HealthCheck.differing_executors,
    HealthCheck.nested_given,
]

station = GroundStation(mission=build_sim(Scenario(vehicles=3, seed=3)).mission, control_period_s=0.05)
for _ in range(20):
    station.tick()
app = create_app(station, viser_port=1)
LOOPBACK = {"host": "127.0.0.1"}  # the station without sign-in answers only to loopback host names
schema = schemathesis.openapi.from_asgi("/openapi.json", app, headers=LOOPBACK)


def digest() -> tuple:
    snap = station.snapshot()
    return (
        snap.formation,
        snap.formation_enabled,
        tuple(o.obstacle_id for o in snap.obstacles),
        tuple(v.phase for v in snap.vehicles),
    )


@schema.parametrize()
@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=ALL_HEALTH_CHECKS,
    derandomize=True,
)
def test_every_operation_conforms_and_refusals_change_nothing(case):
    before = digest()
    response = case.call(headers=LOOPBACK)
    # a schema-valid command the station refuses (d_des outside the range for the team size now, releasing a
    # flying MAV) is a documented 422 with a Problem body: its limits change with the state, so the schema
    # cannot state them and "schema-valid must be accepted" does not apply
    case.validate_response(response, excluded_checks=[positive_data_acceptance])
    assert response.status_code < 500
    if response.status_code >= 400:
        assert digest() == before, (
            f"{case.method} {case.path} was refused ({response.status_code}) but changed state"
        )
