"""The paper's experiments: the protocol (runs x methods x parameters x checkpoints), a
resumable result store, and the tables and figures drawn from it."""

from lfmdr_gym.experiments.protocol import (
    Episode,
    ProtocolConfig,
    ProtocolSummary,
    collect_history,
    evaluate,
    map_history_file,
    run_episode,
    run_protocol,
)
from lfmdr_gym.experiments.store import ResultStore, SettingsMismatchError, read_results

__all__ = [
    "Episode",
    "ProtocolConfig",
    "ProtocolSummary",
    "ResultStore",
    "SettingsMismatchError",
    "collect_history",
    "evaluate",
    "map_history_file",
    "read_results",
    "run_episode",
    "run_protocol",
]
