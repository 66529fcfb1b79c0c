"""The voice: the interface the game sees (api), settings, the speaker with its queue,
timeouts and engines (speaker) and the simulated twin (sim)."""
