"""STAR-loc's left camera alone with SPATIAL-BA's incremental start (issue 34), when
``<repo>/../shared/data/starloc`` exists."""

from __future__ import annotations

import warnings

import pytest
from paths import SHARED_DATA

from lfmdr_gym.experiments.starloc import STARLOC_PARAMS, map_starloc

DATA = SHARED_DATA / "starloc"


@pytest.mark.slow
@pytest.mark.skipif(not (DATA / "data").is_dir(), reason=f"STAR-loc data not found at {DATA}")
def test_zigzag_s3_rays_alone_from_merged_pieces():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the map's notes on unmapped tags
        r = map_starloc(DATA / "data" / "zigzag_s3", "bearing",
                        {**STARLOC_PARAMS["bearing"], "start": "incremental"})
    # measured 0.37 m, 86 % mapped; from the anchors (the default start) 1.45 m
    assert r.mpe < 0.6 and r.mapped >= 0.8
