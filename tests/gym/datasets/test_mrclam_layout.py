"""An MRCLAM folder that is missing or incomplete: the error names what is missing and where the
dataset is published."""

import pytest

from lfmdr_gym.cli import main
from lfmdr_gym.datasets.mrclam import read_run
from lfmdr_gym.datasets.mrclam_layout import MRCLAM_URL, MRCLAMLayoutError, check_run_layout


def test_missing_folder_says_where_to_get_the_data(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist") as exc:
        read_run(tmp_path / "MRCLAM_Dataset9")
    assert MRCLAM_URL in str(exc.value)
    (tmp_path / "a_file").write_text("")
    with pytest.raises(MRCLAMLayoutError, match="is not a folder"):
        check_run_layout(tmp_path / "a_file", (1,))


def test_missing_files_are_named(tmp_path):
    (tmp_path / "Barcodes.dat").write_text("# header\n")
    (tmp_path / "Robot1_Measurement.dat").write_text("# header\n")
    with pytest.raises(ValueError, match="lacks Landmark_Groundtruth.dat, Robot2_Measurement.dat$"
                       .replace("$", r"\. MRCLAM runs are published")) as exc:
        check_run_layout(tmp_path, (1, 2))
    assert isinstance(exc.value, FileNotFoundError)


def test_cli_reports_the_missing_folder_in_one_line(tmp_path, capsys):
    assert main(["mrclam", str(tmp_path / "nowhere"), "--sensor", "range"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "does not exist" in err and MRCLAM_URL in err
