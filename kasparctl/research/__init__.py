"""Research data from recorded sessions: the session list, tidy CSV, figures and summaries.

Read-only over a state directory: listing, exporting or reporting never
changes a session (a torn line is reported, not repaired; repairing is the
robot's job when it resumes). Only `figures` needs matplotlib, imported when
a report draws.
"""
