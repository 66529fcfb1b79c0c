"""The game: the five-step machine (machine), its state and the records that change it
(state), crash-safe sessions on disk (session), problems, phrases and the diagram."""
