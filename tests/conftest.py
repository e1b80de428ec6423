"""Session set-up shared by every test directory."""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from xdist.remote import Producer
    from xdist.scheduler import LoadScopeScheduling


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels() -> None:
    """Load (or, on a fresh install, compile) the controller's numba kernels before the first test, so that no
    test with a wall-clock time-out pays for a compile (`make test` compiles them before pytest starts)."""
    from controller.warmup import warm_up

    warm_up()


# ---- distribution over `make test`'s workers (pytest -n auto --dist loadgroup) -----------------------------
# What the default distribution (--dist load) gets wrong for this suite, paid in wall time:
# - it deals a module's tests out to both workers in chunks, so a module-scoped fixture that starts something
#   expensive (a live ground station, five agent processes, an experiment of 21 runs) is started once on each
#   worker that runs one of its tests: the tests of a module that share such a fixture form one xdist group
#   (one worker, one set-up);
# - the longest tests (browser tests over live stations, the agents' rehearsal) come last in collection order,
#   so one worker is left finishing them while the other idles: the longest units start first (LONGEST, then
#   every unit with a FIRST_MARKS test), and the many short tests fill in behind them.
# Without xdist only the order changes; the tests of a group stay together, in their own order.

FIRST_MARKS = ("slow", "browser", "e2e")
# The longest units, longest first (wall seconds of each on the 2-core machine under `make test`'s load):
# a group's name (module::fixture) or a nodeid prefix.
LONGEST = (
    "tests/server/lab/test_experiments.py::quick_all",  # 140-150 s (2026-11-30): `experiment all --quick`
    "tests/webui/test_agents_spawn.py::spawned",  # 150-170 s: the 60 s rehearsal, web load, a browser
    "tests/webui/test_browser.py::live",  # 130-150 s: a live station and eleven browser tests
    "tests/server/lab/test_experiments.py::ordering",  # 95-110 s (2026-11-30): 21 runs of 45 s, 2 processes
    "tests/server/lab/test_sim_acceptance.py::paper_run",  # 13 flights of 120 s (K = 3, 5, 8, seeds 1-4)
    # The PX4 tests wait on real-time peers with the CPU mostly idle (2026-12-06: scenarios 158 s of wall time
    # for 57 s of CPU, link 73 s for 5 s, e2e 38 s for 8 s). Collected last, they ran last and ended the
    # parallel pass alone for half a minute; started early, they overlap the CPU-bound runs.
    "tests/vehicles/px4/test_px4_scenarios.py",
    "tests/vehicles/px4/test_px4_link.py",
    "tests/vehicles/px4/test_px4_e2e.py",
    "tests/webui/test_browser_security.py::secured_live",  # 110 s
    "tests/webui/test_operator_page.py::test_land_all_is_reachable",  # 45-55 s (3 MAVs; 16 run `alone`)
)


def _module_fixture_keys(item: pytest.Item) -> list[str]:
    """The module-, class- or package-scoped fixtures of this project that `item` uses, each named after
    the instance it shares with other tests (plugins' fixtures, with baseid "", are left out)."""
    if not isinstance(item, pytest.Function):
        return []
    module = item.nodeid.split("::", 1)[0]
    keys = []
    for name in item.fixturenames:
        defs = item._fixtureinfo.name2fixturedefs.get(name)
        if not defs:
            continue
        fixturedef = defs[-1]
        if fixturedef.baseid and fixturedef.scope in ("module", "class", "package"):
            where = fixturedef.baseid if fixturedef.scope == "package" else module
            keys.append(f"{where}::{name}")
    return keys


def _groups(items: list[pytest.Item]) -> dict[pytest.Item, str]:
    """Per item, its group: the items that share a fixture instance with it, directly or through other
    items, named after the first such fixture. Items that share none are left out."""
    parent: dict[str, str] = {}

    def root(key: str) -> str:
        while parent[key] != key:
            parent[key] = parent[parent[key]]
            key = parent[key]
        return key

    per_item: dict[pytest.Item, list[str]] = {}
    for item in items:
        keys = _module_fixture_keys(item)
        if not keys:
            continue
        per_item[item] = keys
        for key in keys:
            parent.setdefault(key, key)
        first = root(keys[0])
        for key in keys[1:]:
            other = root(key)
            if other != first:
                parent[other] = first
    return {item: root(keys[0]) for item, keys in per_item.items()}


def _rank(name: str, unit: list[pytest.Item]) -> int:
    for rank, prefix in enumerate(LONGEST):
        if name.startswith(prefix):
            return rank
    if any(item.get_closest_marker(mark) for item in unit for mark in FIRST_MARKS):
        return len(LONGEST)
    return len(LONGEST) + 1


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> Iterator[None]:
    """Mark each group before the other hooks run; once they have run (deselection, pytest's own reordering),
    order the units by _rank, keeping each one's tests together and otherwise the order they came in. The
    first xdist worker leaves the groups, by nodeid, for the scheduler (see pytest_xdist_make_scheduler)."""
    for item, group in _groups(items).items():
        item.add_marker(pytest.mark.xdist_group(group))
    yield
    units: dict[str, list[pytest.Item]] = {}
    for item in items:
        mark = item.get_closest_marker("xdist_group")
        units.setdefault(str(mark.args[0]) if mark is not None else item.nodeid, []).append(item)
    ordered = sorted(units.items(), key=lambda named: _rank(*named))
    items[:] = [item for _, unit in ordered for item in unit]
    if os.environ.get("PYTEST_XDIST_WORKER") == "gw0" and config.cache is not None:
        groups = {item.nodeid: name for name, unit in ordered for item in unit if name != item.nodeid}
        config.cache.set(GROUPS_CACHE_KEY, groups)


GROUPS_CACHE_KEY = "skyring/xdist-groups"


@pytest.hookimpl(optionalhook=True)  # xdist's hook: unknown under -p no:xdist
def pytest_xdist_make_scheduler(config: pytest.Config, log: Producer) -> LoadScopeScheduling | None:
    """`--dist loadgroup`, with the groups passed from the workers' collection as above. xdist's own passes
    them by appending "@group" to each nodeid, which pytest 9.2's structured node ids silently ignore (a known
    xdist bug with pytest 9.2): every test went out on its own. Other --dist modes are xdist's."""
    if config.getoption("dist", None) != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedFixtureScheduling(LoadScopeScheduling):
        """Units of work: a group's tests together, every other test on its own, in collection order."""

        groups: dict[str, str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self.groups is None:  # the workers have all collected (and written them) by the first call
                assert config.cache is not None
                self.groups = config.cache.get(GROUPS_CACHE_KEY, {})
            assert self.groups is not None
            return self.groups.get(nodeid, nodeid)

    return SharedFixtureScheduling(config, log)
