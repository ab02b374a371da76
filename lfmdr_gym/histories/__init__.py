"""Observation histories: the :class:`History` a mapper takes, how an episode is recorded into
one (:func:`collect`, :func:`collect_vector`), and the compact storage of large ones."""

from lfmdr_gym.histories.history import History, HistoryFileError
from lfmdr_gym.histories.recording import collect, collect_vector

__all__ = ["History", "HistoryFileError", "collect", "collect_vector"]
