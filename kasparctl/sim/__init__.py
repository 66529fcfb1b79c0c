"""Simulation: simulated time, simulated children and teachers, the demo, the simulator and
its vectorised sweep, and the replication of demo games against the simulator."""
