"""The live ground station: the mission it supervises, operator commands and their validation, the REST and
WebSocket API, the real-time loop, and the PX4 mode."""
