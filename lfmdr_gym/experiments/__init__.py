"""The experiments: where the world's histories meet the mappers.

``protocol`` runs the paper's protocol (runs x methods x parameters x checkpoints) on an
``engine`` (this process, local workers or a Dask cluster) into a resumable ``store``; ``figures``
draws its tables and figures; ``mapping`` makes single maps (``lfmdr run``, ``lfmdr map``);
``mrclam`` maps real robot runs; ``reproducibility`` records environments and compares tables.
"""

from lfmdr_gym.experiments.episodes import Episode, collect_episode, collect_history
from lfmdr_gym.experiments.mapping import map_history_file, run_episode
from lfmdr_gym.experiments.protocol import ProtocolConfig, ProtocolSummary, run_protocol
from lfmdr_gym.experiments.reproducibility import compare_tables
from lfmdr_gym.experiments.scoring import evaluate, map_history, score_map
from lfmdr_gym.experiments.store import ResultStore, SettingsMismatchError, read_results

__all__ = [
    "Episode", "collect_episode", "collect_history",
    "map_history_file", "run_episode",
    "ProtocolConfig", "ProtocolSummary", "run_protocol",
    "compare_tables",
    "evaluate", "map_history", "score_map",
    "ResultStore", "SettingsMismatchError", "read_results",
]
