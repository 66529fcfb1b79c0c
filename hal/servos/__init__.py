"""The servos: the interface the game sees (api), settings, the joints layer that enforces
safety, one owner thread per serial port (bus), a driver per protocol family and the
simulated twin (sim)."""
