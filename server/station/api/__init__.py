"""The ground station's HTTP front (REST, WebSocket, sign-in, the operator page), built by
`app.create_app`."""
