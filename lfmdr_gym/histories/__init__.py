"""Observation histories: the History a mapper takes, how an episode is recorded into one, and its compact storage."""
