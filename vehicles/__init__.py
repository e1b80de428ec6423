"""What flies and what it sees: the onboard agent loop, autopilot back-ends (simulated; PX4 through MAVSDK),
the camera and detector model, the simulated world, and the links between MAVs. Imports `controller` only."""
