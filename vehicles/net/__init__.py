"""Networked agents: the wire format, key expressions, the Zenoh transport, and the onboard runner."""
