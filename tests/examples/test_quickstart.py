"""The quick start example runs and says what it measured, with label and unit."""

import runpy

from paths import EXAMPLES


def test_quickstart_prints_labelled_scores(tmp_path, capsys):
    script = EXAMPLES / "quickstart.py"
    main = runpy.run_path(str(script))["main"]
    history = main(["--steps", "600", "--out", str(tmp_path / "h.npz")])
    out = capsys.readouterr().out
    assert history.n_steps == 600 and (tmp_path / "h.npz").is_file()
    lines = [line for line in out.splitlines() if "MPE" in line]
    assert [line.split(":")[0].strip() for line in lines] == ["SMA(WGT)", "CAL-SMA"]
    for line in lines:
        mpe = float(line.split("MPE ")[1].split(" m")[0])
        assert 0 < mpe < 0.5 and "m (non-anchor objects), MOE" in line
