"""The voice: Kaspar's lines, spoken or written to WAV files.

The interface the game sees (api), settings, the speaker (Voice: its queue,
timeouts and fallback), its engines (espeak, pyttsx3_thread), where the sound
goes (sinks), their child processes (processes) and the simulated twin (sim).
"""
