"""Learning: the paper's learner (learner, imports nothing of the project) and the statistics
of studies and sessions computed from problems."""
