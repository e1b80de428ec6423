"""When the Team tab offers Release for the chosen MAV (webui/team_panel.py)."""

from __future__ import annotations

import pytest
from scene_views import flying_mav

from webui.team_panel import releasable


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
    assert releasable(flying_mav(**changes)) is offered
