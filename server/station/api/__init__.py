"""The ground station's HTTP front (REST, WebSocket, sign-in, the operator page): see `app.py`."""

from server.station.api.app import create_app

__all__ = ["create_app"]
