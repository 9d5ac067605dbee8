"""Nothing a user wrote is overwritten: a file of an earlier output folder that was changed since shevsim wrote it
(a hand-edited ``params.toml`` of a calibration) is refused on a re-run into that folder, naming it; files exactly
as shevsim wrote them are replaced; a crash between two files leaves a folder a re-run accepts."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from shevsim.core import atomic
from shevsim.core.atomic import MANIFEST, edited_outputs, write_files
from shevsim.core.errors import ShevsimError


def _crash_on(n: int, calls: list):
    """A stand-in for `atomic.write_bytes_atomic` that raises on its ``n``-th call (the calls' paths in ``calls``)."""
    real = atomic.write_bytes_atomic

    def write(path, data):
        calls.append(path)
        if len(calls) == n:
            raise OSError("disk gone")
        return real(path, data)
    return write


def _files(v: str) -> dict[str, bytes]:
    return {"params.toml": f"[params]\nx = {v}\n".encode(), "report.md": f"# {v}\n".encode(),
            "report.json": json.dumps({"v": v}).encode()}


def test_rerun_replaces_own_files_and_refuses_an_edited_one(tmp_path):
    out = tmp_path / "cal"
    write_files(out, _files("1"), "report.json", "calibrate cell")
    assert (out / MANIFEST).is_file()
    write_files(out, _files("2"), "report.json", "calibrate cell")          # untouched: replaced
    assert (out / "params.toml").read_text() == "[params]\nx = 2\n"
    (out / "params.toml").write_text("[params]\nx = 2  # mine\n")          # the user's edit
    with pytest.raises(ShevsimError, match=r"params\.toml' was changed since shevsim wrote it"):
        write_files(out, _files("3"), "report.json", "calibrate cell")
    assert (out / "params.toml").read_text() == "[params]\nx = 2  # mine\n"  # kept
    assert (out / "report.md").read_text() == "# 2\n"                       # nothing written before the refusal


def test_a_file_the_user_put_beside_an_output_under_one_of_its_names_is_refused(tmp_path):
    out = tmp_path / "cal"
    write_files(out, {"report.json": b"{}", "report.md": b"#"}, "report.json", "calibrate cell")
    (out / "params.toml").write_text("mine\n")              # not written by the earlier output
    assert edited_outputs(out, ["params.toml", "report.md"], "report.json") == ["params.toml"]
    with pytest.raises(ShevsimError, match="params.toml"):
        write_files(out, _files("1"), "report.json", "calibrate cell")
    assert (out / "params.toml").read_text() == "mine\n"


def test_an_older_output_without_manifest_falls_back_on_modification_times(tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    for n, b in _files("1").items():
        (out / n).write_bytes(b)
    t = (out / "report.json").stat().st_mtime
    os.utime(out / "params.toml", (t - 5, t - 5))
    os.utime(out / "report.md", (t - 5, t - 5))
    assert edited_outputs(out, list(_files("1")), "report.json") == []
    os.utime(out / "params.toml", (t + 60, t + 60))                         # edited after the marker
    assert edited_outputs(out, list(_files("1")), "report.json") == ["params.toml"]
    with pytest.raises(ShevsimError, match="params.toml"):
        write_files(out, _files("2"), "report.json", "calibrate cell")
    os.utime(out / "params.toml", (t - 5, t - 5))
    write_files(out, _files("2"), "report.json", "calibrate cell")          # now taken as ours
    assert json.loads((out / MANIFEST).read_text())["sha256"].keys() >= set(_files("2"))


def test_a_crash_between_two_files_leaves_a_folder_a_rerun_accepts(tmp_path, monkeypatch):
    out = tmp_path / "cal"
    write_files(out, _files("1"), "report.json", "calibrate cell")
    real = atomic.write_bytes_atomic
    calls: list = []
    # 1: the manifest (both hashes), 2: params.toml, 3: report.md (crashes)
    monkeypatch.setattr(atomic, "write_bytes_atomic", _crash_on(3, calls))
    with pytest.raises(OSError):
        write_files(out, _files("2"), "report.json", "calibrate cell")
    monkeypatch.setattr(atomic, "write_bytes_atomic", real)
    assert [Path(c).name for c in calls] == [MANIFEST, "params.toml", "report.md"]
    assert (out / "params.toml").read_text() == "[params]\nx = 2\n" and (out / "report.md").read_text() == "# 1\n"
    # one file new, one old: both hashes are listed, so the re-run is not refused
    assert edited_outputs(out, list(_files("2")), "report.json") == []
    write_files(out, _files("3"), "report.json", "calibrate cell")
    assert (out / "report.md").read_text() == "# 3\n"


def test_calibrate_refuses_before_the_fit_when_params_toml_was_edited(tmp_path):
    from shevsim.calibrate.report import check_calibration_out
    out = tmp_path / "cal"
    write_files(out, _files("1"), "report.json", "calibrate cell")
    check_calibration_out(out, "cell")                                     # as written: fine
    with open(out / "params.toml", "a") as f:
        f.write("# tuned by hand\n")
    with pytest.raises(ShevsimError, match=r"calibrate cell: .*params\.toml' was changed"):
        check_calibration_out(out, "cell")


def test_a_crash_during_the_first_save_leaves_a_folder_the_next_run_accepts(tmp_path, monkeypatch):
    out = tmp_path / "cal"
    real = atomic.write_bytes_atomic
    monkeypatch.setattr(atomic, "write_bytes_atomic", _crash_on(3, []))
    with pytest.raises(OSError):
        write_files(out, _files("1"), "report.json", "calibrate cell")
    monkeypatch.setattr(atomic, "write_bytes_atomic", real)
    assert (out / "params.toml").is_file() and not (out / "report.json").exists()
    write_files(out, _files("2"), "report.json", "calibrate cell")         # listed as written: accepted
    assert (out / "params.toml").read_text() == "[params]\nx = 2\n"
    # but a file of the user's of one of those names in a folder without the marker is still refused
    other = tmp_path / "mine"
    other.mkdir()
    (other / "params.toml").write_text("mine\n")
    with pytest.raises(ShevsimError, match="holds files but no report.json"):
        write_files(other, _files("1"), "report.json", "calibrate cell")


def test_two_kinds_of_output_in_one_folder_keep_each_others_hashes(tmp_path):
    out = tmp_path / "both"
    write_files(out, _files("1"), "report.json", "calibrate cell")
    write_files(out, {"summary.json": b"{}", "table.csv": b"a\n1\n"}, "summary.json", "study tradeoff")
    write_files(out, _files("2"), "report.json", "calibrate cell")          # untouched: not refused
    write_files(out, {"summary.json": b"{}", "table.csv": b"a\n2\n"}, "summary.json", "study tradeoff")
    assert (out / "params.toml").read_text() == "[params]\nx = 2\n" and (out / "table.csv").read_text() == "a\n2\n"


def test_an_older_output_is_adopted_whole_so_a_figure_left_out_once_is_still_ours(tmp_path):
    out = tmp_path / "old"
    out.mkdir()
    files = {**_files("1"), "maps.png": b"\x89PNG..."}
    for n, b in files.items():
        (out / n).write_bytes(b)
    t = (out / "report.json").stat().st_mtime
    for n in files:
        os.utime(out / n, (t - 5, t - 5))
    os.utime(out / "report.json", (t, t))
    write_files(out, _files("2"), "report.json", "calibrate cell")          # without the figure
    write_files(out, {**_files("3"), "maps.png": b"\x89PNG2"}, "report.json", "calibrate cell")
    assert (out / "maps.png").read_bytes() == b"\x89PNG2"


def test_a_study_refuses_before_it_runs_when_a_file_of_its_earlier_output_was_edited(tmp_path):
    from shevsim.studies.result import check_study_out
    out = tmp_path / "st"
    write_files(out, {"summary.json": b"{}", "tradeoff.csv": b"rate\n1\n"}, "summary.json", "study tradeoff")
    check_study_out(out, "tradeoff")                                        # as written: fine
    (out / "tradeoff.csv").write_text("rate\n1\n2\n")
    with pytest.raises(ShevsimError, match=r"study tradeoff: .*tradeoff\.csv' was changed"):
        check_study_out(out, "tradeoff")
