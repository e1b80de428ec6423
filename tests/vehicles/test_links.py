"""The emulated radio links: broadcast, loss, latency, jitter, determinism."""

import numpy as np
import pytest

from controller.messages import Detection
from vehicles.links import LinkParams, SimLinks


def _det(source, stamp):
    return Detection(source_id=source, stamp_s=stamp, position_m=np.array((0, 0, 0.9)), cov_m2=np.eye(3))


def _links(loss=0.0, latency=0.05, jitter=0.0, seed=0, ids=(1, 2, 3)):
    return SimLinks(
        vehicle_ids=ids,
        params=LinkParams(loss=loss, latency_s=latency, jitter_s=jitter),
        rng=np.random.default_rng(seed),
    )


def test_a_message_reaches_every_teammate_after_the_latency_and_not_the_sender():
    links = _links()
    msg = _det(1, 0.0)
    links.send(0.0, 1, msg)
    assert links.receive(0.04, 2) == ()
    assert links.receive(0.05, 2) == (msg,)
    assert links.receive(0.05, 3) == (msg,)
    assert links.receive(1.0, 1) == ()
    assert links.receive(1.0, 2) == ()  # received once only
    assert links.stats().delivered == 2


def test_total_loss_delivers_nothing():
    links = _links(loss=1.0)
    for i in range(100):
        links.send(i * 0.1, 1, _det(1, i * 0.1))
    assert links.receive(100.0, 2) == () and links.receive(100.0, 3) == ()
    stats = links.stats()
    assert (stats.sent, stats.dropped, stats.delivered) == (200, 200, 0)


def test_partial_loss_delivers_the_complementary_fraction():
    links = _links(loss=0.3, ids=(1, 2))
    for i in range(20000):
        links.send(i * 0.01, 1, _det(1, i * 0.01))
    delivered = len(links.receive(1e6, 2))
    assert delivered / 20000 == pytest.approx(0.7, abs=0.01)


def test_jitter_delivers_within_latency_plus_jitter_and_may_reorder():
    links = _links(latency=0.03, jitter=0.05, ids=(1, 2))
    sent = [_det(1, i * 0.01) for i in range(200)]
    for m in sent:
        links.send(m.stamp_s, 1, m)
    got = []
    for step in range(1, 400):
        now = step * 0.01
        for m in links.receive(now, 2):
            assert 0.03 - 1e-9 <= now - m.stamp_s <= 0.03 + 0.05 + 0.01 + 1e-9
            got.append(m.stamp_s)
    assert sorted(got) == [m.stamp_s for m in sent]
    assert got != sorted(got)


def test_same_seed_same_deliveries_different_seed_different():
    def delivered(seed):
        links = _links(loss=0.5, seed=seed, ids=(1, 2))
        for i in range(200):
            links.send(i * 0.1, 1, _det(1, i * 0.1))
        return [m.stamp_s for m in links.receive(1e6, 2)]

    assert delivered(1) == delivered(1)
    assert delivered(1) != delivered(2)


@pytest.mark.parametrize(
    "kwargs",
    [{"loss": -0.1}, {"loss": 1.5}, {"loss": float("nan")}, {"latency_s": -1.0}, {"jitter_s": float("inf")}],
)
def test_bad_link_parameters_are_rejected(kwargs):
    with pytest.raises(ValueError, match="link"):
        LinkParams(**kwargs)
