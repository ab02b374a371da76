"""A map's warnings in the words of the data: the objects they name as landmark ids, not rows.

``mappers`` name objects by their row in the history it was given ("objects [9, 27] could not be
placed"). A user mapping a log (``lfmdr map``, ``lfmdr mrclam``) knows them by their landmark ids;
the commands print the map's warnings with each bracketed list of rows that follows an object
phrase ("objects", "groups", "pair distance(s)", "anchors", ...) rewritten as those ids.

A method's own warning, as ``build_map`` records it (``"LOC-SMA: RigidityWarning: ..."``), counts
rows among the objects it was given: those with an observation (:func:`rows_with_data`), not all
of the history's.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = ["landmark_notes", "name_rows", "rows_with_data"]

# Phrases of the mappers' warnings followed by a bracketed list of object rows, and how they read
# once the rows are landmark ids.
_ROW_PHRASES = {
    r"objects": "landmarks",
    r"object\(s\) \(rows\)": "landmark(s)",
    r"groups": "groups of landmarks",
    r"pair distance\(s\)": "pair distance(s) between landmarks",
    r"anchors": "anchors",
}
_ROW_LIST = re.compile(r"\b(" + "|".join(_ROW_PHRASES) + r") (?=\[)")
_METHOD_NOTE = re.compile(r"^[^\s:]+: [A-Za-z]*Warning: ")


def _bracketed(text: str, start: int) -> int:
    """The index just past the bracket that closes the one at ``text[start]``."""
    depth = 0
    for k in range(start, len(text)):
        depth += {"[": 1, "(": 1, "]": -1, ")": -1}.get(text[k], 0)
        if depth == 0:
            return k + 1
    return len(text)


def _id_text(value: Any) -> str:
    """A landmark id as the data writes it (a numpy integer as a plain integer)."""
    return str(int(value)) if isinstance(value, (int, np.integer)) else str(value)


def name_rows(note: str, ids: Sequence[Any] | np.ndarray, rows: np.ndarray) -> str:
    """``note`` with the object rows it names (after ``objects``, ``groups``, ``pair
    distance(s)``, ``anchors``...) written as landmark ids: row ``k`` is ``ids[rows[k]]``; a
    number outside ``rows`` is left as it is."""
    out, at = [], 0
    for match in _ROW_LIST.finditer(note):
        if match.start() < at:
            continue
        end = _bracketed(note, match.end())
        words = next(v for k, v in _ROW_PHRASES.items() if re.fullmatch(k, match.group(1)))
        named = re.sub(r"\d+", lambda m: (_id_text(ids[rows[int(m.group())]])
                                          if int(m.group()) < len(rows) else m.group()),
                       note[match.end():end])
        out += [note[at:match.start()], f"{words} {named}"]
        at = end
    return "".join(out) + note[at:]


def rows_with_data(histories: Any) -> np.ndarray:
    """The rows ``build_map`` hands a method: the objects with an observed non-zero entry in a
    History or in any part of a fused one (a mapping sensor -> History)."""
    parts = histories.values() if isinstance(histories, dict) else [histories]
    rows = None
    for h in parts:
        X = np.asarray(h.matrix) != 0
        has = np.any(X if h.mask is None else X & np.asarray(h.mask), axis=1)
        rows = has if rows is None else rows | has
    return np.flatnonzero(rows)


def landmark_notes(notes: Iterable[str], ids: Sequence[Any] | np.ndarray,
                   histories: Any) -> list[str]:
    """The map's warnings ``notes`` with the rows they name as the landmark ``ids`` (one per
    row of the ``histories`` mapped; the module's docstring)."""
    every, fitted = np.arange(len(ids)), None
    out = []
    for note in notes:
        if _METHOD_NOTE.match(note):
            fitted = rows_with_data(histories) if fitted is None else fitted
            out.append(name_rows(note, ids, fitted))
        else:
            out.append(name_rows(note, ids, every))
    return out
