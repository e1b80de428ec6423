"""PX4 vehicles through MAVSDK 4: the autopilot back-end, who may fly the vehicle (the supervisor), and the
geodetic frames at the PX4 edge."""
