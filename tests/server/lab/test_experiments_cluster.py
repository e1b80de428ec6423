"""`skyring experiment --cluster`: a sweep's runs on a Dask cluster give the same reports as on the local
process pool. The cluster here is a local one with 2 worker processes on 127.0.0.1, stopped by the test."""

from __future__ import annotations

import json

import pytest
from distributed import LocalCluster

from server.lab import experiments as exp
from server.lab.numeric_platform import numeric_platform
from server.lab.simulation import without_timings

CONDITIONS = tuple(
    exp.Condition(
        name=f"{k} MAVs",
        x=float(k),
        settings=(("vehicles", k), ("trees", "paper"), ("warmup_s", 4.0), ("rate_hz", 10.0)),
    )
    for k in (2, 3)
)


def _specs() -> list[exp.RunSpec]:
    protocol = exp.Protocol("scalability", CONDITIONS, (9.0,), rate_hz=10.0)
    return exp.plan_runs([protocol], base_seed=7)


@pytest.fixture(scope="module")
def cluster():
    local = LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address="127.0.0.1:0"
    )
    try:
        yield local.scheduler_address
    finally:
        local.close()


def _reports(results: list[exp.RunResult]) -> list[dict]:
    assert all(r.ok for r in results), [r.error for r in results]
    return [without_timings(json.loads(json.dumps(r.report))) for r in results]


@pytest.mark.e2e
def test_cluster_runs_equal_the_local_runs(cluster, tmp_path):
    specs = _specs()
    local = exp.run_all(specs, jobs=2, out_dir=tmp_path / "local")
    remote = exp.run_all(specs, jobs=1, out_dir=tmp_path / "cluster", cluster=cluster)
    assert [r.spec for r in remote] == specs
    assert _reports(remote) == _reports(local)


@pytest.mark.e2e
def test_cluster_runs_record_the_numeric_platform_they_ran_on(cluster, tmp_path):
    """Workers on this machine: the platform of this process (a cluster of unlike machines would show more
    than one, and the report would say so)."""
    remote = exp.run_all(_specs(), jobs=1, out_dir=tmp_path, cluster=cluster)
    assert exp.platforms(remote) == {numeric_platform(): len(_specs())}


@pytest.mark.e2e
def test_cluster_runs_are_written_where_local_runs_are(cluster, tmp_path):
    specs = _specs()[:1]
    exp.run_all(specs, jobs=1, out_dir=tmp_path, cluster=cluster)
    assert exp.load_run(specs[0], tmp_path) is not None


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="cannot reach the Dask scheduler"):
        exp.run_all(
            _specs()[:1], jobs=1, out_dir=tmp_path, cluster="tcp://127.0.0.1:9", cluster_timeout_s=1.0
        )
