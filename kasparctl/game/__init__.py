"""The game: the five-step machine (machine) and the pure rules it follows.

- stages: the machine's states and transitions as data, and their conditions;
- researcher: keyfob gestures to commands, and where each command applies;
- trial: one guess planned and its answer scored into the trial record;
- presses: the children's keys, an answer or a press to record;
- speech: Kaspar's lines and what a failing voice means;
- records: a typed struct per kind of record; events: what listeners hear;
- state: GameState, changed only by applying records; session: crash-safe
  sessions on disk, the one place records and snapshots are encoded and decoded;
- problem, phrases, diagram: the learned rule, the phrase books, the README's diagram.
"""
