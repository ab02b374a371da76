"""Online maps: the map of a robot still moving, updated as its histories grow.
"""

from __future__ import annotations

from mappers.online.bearing import OnlineBundle
from mappers.online.cal_sma import gram_dissimilarity
from mappers.online.mapper import OnlineMapper
from mappers.online.view_cone import OnlineView

__all__ = ["OnlineBundle", "OnlineMapper", "OnlineView", "gram_dissimilarity"]
