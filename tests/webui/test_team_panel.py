"""When the Team tab offers Release for the chosen MAV (webui/team_panel.py)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from webui.team_panel import releasable
from webui.view import VehicleView


def mav(**changes) -> VehicleView:
    base = VehicleView(
        vehicle_id=1,
        phase="formation",
        mode="offboard",
        armed=True,
        in_air=True,
        in_formation=True,
        position_m=np.array([0.0, 0.0, 9.0]),
        yaw_rad=0.0,
        link_age_s=0.0,
        link_stale=False,
    )
    return dataclasses.replace(base, **changes)


@pytest.mark.parametrize(
    ("changes", "offered"),
    [
        ({}, False),  # flying formation: nothing to give back
        ({"phase": "landed", "in_air": False, "armed": False}, True),
        ({"phase": "holding"}, True),  # rejoins from where it hovers
        ({"phase": "idle", "in_air": False, "armed": False}, False),  # waits for Start formation
        ({"phase": "idle"}, True),  # found flying: joins from the air
        ({"phase": "idle", "failsafe": True}, False),  # ...not while its autopilot runs a failsafe
        ({"released": True}, True),  # a pilot gave it back in the air
        ({"released": True, "failsafe": True}, False),
        ({"phase": "landing"}, False),
    ],
)
def test_release_is_offered_for_a_landed_holding_or_free_airborne_mav_only(changes, offered):
    assert releasable(mav(**changes)) is offered
