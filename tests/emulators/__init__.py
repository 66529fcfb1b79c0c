"""Serial-port emulators of the servos, on pseudo-terminals, for tests and benchmarks only."""
