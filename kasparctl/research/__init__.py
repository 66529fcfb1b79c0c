"""Research data from recorded sessions: the session list, tidy CSV, figures and summaries.

Read-only over state directories (several may be pooled): listing, exporting
or reporting never changes a session (a torn line is reported, not repaired;
repairing is the robot's job when it resumes). Records are streamed
(reader, catalogue, walk), never held whole; a session that cannot be read is
listed with its reason and the rest go on. Outputs are checked against the
inputs and written atomically and private (output). Participants' attributes
are joined from a separate file (participants); the report's intervals are
cluster bootstraps (inference) and its figures are checked for clipped labels
(figures). Only `figures` needs matplotlib, imported when a report draws.
"""
