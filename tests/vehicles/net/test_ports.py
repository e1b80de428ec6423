"""Free ports below the kernel's ephemeral range (vehicles/net/ports.py)."""

from __future__ import annotations

import socket

import pytest

from vehicles.net import ports
from vehicles.net.ports import free_port


@pytest.mark.parametrize(("kind", "sock_type"), [("tcp", socket.SOCK_STREAM), ("udp", socket.SOCK_DGRAM)])
def test_a_port_is_below_the_ephemeral_range_and_binds(kind, sock_type):
    port = free_port(kind)
    assert ports.LOWEST <= port < ports.ephemeral_low()
    with socket.socket(socket.AF_INET, sock_type) as s:
        s.bind(("127.0.0.1", port))


def test_no_port_is_handed_out_twice():
    given = [free_port() for _ in range(300)]
    assert len(set(given)) == 300


def test_a_port_held_by_another_socket_is_not_handed_out(monkeypatch):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        taken = held.getsockname()[1]
        # a range of exactly 101 ports that holds the taken one
        monkeypatch.setattr(ports, "ephemeral_low", lambda: taken + 51)
        monkeypatch.setattr(ports, "SPAN", 100)
        picked = {free_port() for _ in range(20)}
    assert taken not in picked
    assert all(taken - 50 <= p <= taken + 50 for p in picked)


def test_without_room_below_the_range_the_kernel_chooses(monkeypatch):
    monkeypatch.setattr(ports, "ephemeral_low", lambda: 1100)
    port = free_port()
    assert port >= 1100


def test_an_unknown_kind_is_refused():
    with pytest.raises(ValueError, match="'tcp' or 'udp'"):
        free_port("sctp")
