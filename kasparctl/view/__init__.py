"""The researcher's live view of a session: `kasparctl watch`, its replay, `demo --view`.

Read-only by construction: it reads the state directory the game writes
(plan.json, records.jsonl, the daemon's events.jsonl) and never writes, locks
or opens a socket. The layers, each testable alone:

- model: what the view shows, a pure function of the typed records;
- frame: the model laid out as lines of styled text for a screen of a size;
- inotify, follow: which session is live and when its files change (no polling);
- screen: the frame on a terminal (rich, full screen) or as plain text;
- live, replay: the loops that put these together.
"""
