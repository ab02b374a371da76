"""Env keywords in the experiments: parsing, checking, the protocol's settings and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lfmdr_gym.cli import main
from lfmdr_gym.experiments.env_settings import check_env_kwargs, parse_env_kwargs
from lfmdr_gym.experiments.protocol import ProtocolConfig, run_protocol
from lfmdr_gym.experiments.store import SettingsMismatchError
from lfmdr_gym.histories.history import History
from mappers import METHODS

LIMITED = {"fov_deg": 90, "max_range": 1.5, "bearing_noise_deg": 2}


def test_parse_env_kwargs_reads_numbers_booleans_and_none():
    got = parse_env_kwargs(["fov_deg=90", "max_range=1.5", "line_of_sight=True", "max_range_x=none",
                            "anchors=random"])
    assert got == {"fov_deg": 90, "max_range": 1.5, "line_of_sight": True, "max_range_x": None,
                   "anchors": "random"}
    assert isinstance(got["fov_deg"], int) and got["line_of_sight"] is True
    assert parse_env_kwargs(None) == {}


@pytest.mark.parametrize(("items", "problem"), [
    (["fov_deg"], "NAME=VALUE"), (["=3"], "NAME=VALUE"), (["fov_deg="], "NAME=VALUE"),
    (["fov_deg=90", "fov_deg=60"], "'fov_deg' is given twice"),
])
def test_parse_env_kwargs_refuses_bad_items(items, problem):
    with pytest.raises(ValueError, match=problem):
        parse_env_kwargs(items)


def test_check_env_kwargs_names_the_problem():
    with pytest.raises(ValueError, match="unknown env keyword 'fov'"):
        check_env_kwargs("bearing", {"fov": 90})
    with pytest.raises(ValueError, match="'sensor' is set by the experiment"):
        check_env_kwargs("bearing", {"sensor": "range"})
    with pytest.raises(ValueError, match="fov_deg"):
        check_env_kwargs("bearing", {"fov_deg": 0})
    assert check_env_kwargs("bearing", LIMITED) == (LIMITED, True)
    assert check_env_kwargs("bearing", {"n_objects": 30}) == ({"n_objects": 30}, False)
    assert check_env_kwargs("bearing", None) == ({}, False)


def test_protocol_config_with_limits_maps_masked_histories():
    config = ProtocolConfig(sensor="bearing", layouts=1, poses=1, steps=200, env_kwargs=LIMITED)
    assert config.masked
    assert config.methods and all(METHODS[m].takes_masks for m in config.methods)
    assert config.settings()["env_kwargs"] == LIMITED
    assert all(dict(ep.env_kwargs) == LIMITED for ep in config.episodes())
    with pytest.raises(ValueError, match="does not map masked bearing histories"):
        ProtocolConfig(sensor="bearing", env_kwargs=LIMITED, methods=("LPCA",))
    plain = ProtocolConfig(sensor="bearing")
    assert not plain.masked and "env_kwargs" not in plain.settings()  # old manifests resume
    assert not any(METHODS[m].takes_masks for m in plain.methods)


def test_protocol_records_the_settings_and_refuses_others(tmp_path):
    config = ProtocolConfig(sensor="bearing", layouts=1, poses=1, steps=200, every=100,
                            methods=("COVIS-AUTO",), env_kwargs=LIMITED)
    summary = run_protocol(config, tmp_path, progress=False, report=False)
    assert summary.failed == 0 and summary.computed == 2
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["env_kwargs"] == LIMITED
    history = History.load(next((tmp_path / "histories").glob("*.npz")))
    assert history.mask is not None and 0 < history.mask.mean() < 1
    assert history.meta["env_kwargs"]["fov_deg"] == 90
    again = run_protocol(config, tmp_path, progress=False, report=False)
    assert again.computed == 0 and again.resumed == 2
    other = ProtocolConfig(sensor="bearing", layouts=1, poses=1, steps=200, every=100,
                           methods=("COVIS-AUTO",), env_kwargs={**LIMITED, "fov_deg": 60})
    with pytest.raises(SettingsMismatchError, match="env_kwargs"):
        run_protocol(other, tmp_path, progress=False, report=False)


def _error(argv, capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_cli_refuses_unknown_and_bad_env_keywords(tmp_path, capsys):
    err = _error(["reproduce", "--sensor", "bearing", "--env", "fov=90", "--out", str(tmp_path)], capsys)
    assert "unknown env keyword 'fov'" in err
    err = _error(["reproduce", "--sensor", "bearing", "--env", "fov_deg=400", "--out",
                  str(tmp_path)], capsys)
    assert "fov_deg must be in (0, 360]" in err
    err = _error(["run", "--env", "LFMDR-Range-v0", "--env-kw", "miss_rate=0.5", "--steps", "20",
                  "--out", str(tmp_path)], capsys)
    assert "miss_rate applies to the visibility sensor" in err


def test_cli_run_and_collect_pass_env_keywords(tmp_path, capsys):
    code = main(["run", "--env", "LFMDR-Bearing-v0", "--env-kw", "fov_deg=90", "--env-kw",
                 "max_range=1.5", "--steps", "300", "--every", "300", "--out", str(tmp_path / "r")])
    assert code == 0
    out = capsys.readouterr().out
    assert "BEARING-BA" in out  # the masked bearing default
    history = History.load(tmp_path / "r" / "history.npz")
    assert history.mask is not None and history.meta["env_kwargs"]["max_range"] == 1.5
    code = main(["collect", "--env", "LFMDR-Visibility-v0", "--env-kw", "fov_deg=60", "--steps", "50",
                 "--out", str(tmp_path / "c.npz")])
    assert code == 0
    assert "observed entries" in capsys.readouterr().out
    history = History.load(tmp_path / "c.npz")
    assert history.mask is not None and not np.any(history.matrix[~history.mask])
