"""The embedded simulator: simulated multirotors and their autopilot, the person, tree trunks, GPS drift, the
world that moves them and emulates each MAV's camera and detector, and the builder every mode uses."""
