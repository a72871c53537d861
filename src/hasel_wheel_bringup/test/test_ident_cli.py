"""``hasel_wheel trials`` and ``hasel_wheel identify`` end to end, on short CSV trials."""
import json
import math
import os

from hasel_wheel_bringup.cli import main
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.data import write_csv
from hasel_wheel_ident.numerics import blas_in_use
from hasel_wheel_sim.plant import PlantConfig


def test_identify_writes_the_report_from_csv_files(tmp_path, capsys):
    specs = tuple(S.SyntheticTrial(math.radians(a), drive=12.0, coast=6.0) for a in (2.0, 6.0))
    paths = []
    for tr in S.record_set(specs, config=PlantConfig(seed=4, switching="tick")):
        paths.append(tmp_path / f"{tr.name}.csv")
        write_csv(tr, paths[-1])
    out = tmp_path / "report"
    rc = main(["identify", *map(str, paths), "--out", str(out), "--folds", "2",
               "--only", "viscous_drag,com_offset", "--quiet"])
    assert rc == 0
    data = json.loads((out / "report.json").read_text())
    assert data["chosen_effects"] == [] and data["unexplained"] == []
    assert {t["name"] for t in data["trials"]} == {"phi_a_2deg", "phi_a_6deg"}
    assert {c["id"] for c in data["candidates"]} == {"viscous_drag", "com_offset"}
    assert not any(c["ran_on"] for c in data["candidates"] + data["tried_together"])
    assert data["near_misses"] == []
    assert (out / "model.yaml").exists() and (out / "report.md").exists()
    assert "chosen effects: none" in capsys.readouterr().out
    # the BLAS that ran the fits is on record (empty without threadpoolctl)
    assert data["numerics"] == blas_in_use()
    assert data["numerics"]["coretype_env"] == os.environ.get("OPENBLAS_CORETYPE")


def test_identify_names_the_row_and_column_of_a_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,angle,q,eta,n_a,phi_a,phi_d\n0.0,0.1,0,0,-1,,\n0.0033,0.2,7,0,-1,,\n")
    assert main(["identify", str(bad), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "row 3, column q: 7 is outside 0..1" in err


def test_an_unknown_candidate_is_refused_with_the_known_ones(tmp_path, capsys):
    bad = tmp_path / "x.csv"
    bad.write_text("t,angle,q,eta,n_a,phi_a,phi_d\n")
    assert main(["identify", str(bad), "--only", "warp_drive", "--out", str(tmp_path)]) == 2
    assert "warp_drive" in capsys.readouterr().err


def test_one_trial_is_refused_because_nothing_could_be_held_out(tmp_path, capsys):
    tr = S.record(S.SyntheticTrial(math.radians(3.0), drive=5.0, coast=2.0))
    write_csv(tr, tmp_path / "one.csv")
    assert main(["identify", str(tmp_path / "one.csv"), "--out", str(tmp_path / "r")]) == 2
    assert "at least 2 trials" in capsys.readouterr().err


def test_trials_recorded_as_a_session_are_identified_in_session_order(tmp_path):
    trials = tmp_path / "trials"
    assert main(["trials", "--out", str(trials), "--phi-a-deg", "6", "2", "--drive", "12",
                 "--coast", "6", "--session-gap", "5"]) == 0
    paths = sorted(trials.glob("*.csv"), reverse=True)    # not the order they ran in
    assert all("session_t" in p.read_text().splitlines()[0].split(",") for p in paths)
    out = tmp_path / "report"
    assert main(["identify", *map(str, paths), "--out", str(out), "--folds", "2",
                 "--only", "viscous_drag", "--quiet"]) == 0
    ses = json.loads((out / "report.json").read_text())["session"]
    assert ses["timed"] is True and ses["warning"] is None
    assert [t["name"] for t in ses["trials"]] == ["session1_phi_a_6deg", "session2_phi_a_2deg"]
    assert ses["trials"][0]["gap_s"] is None
    assert abs(ses["trials"][1]["gap_s"] - 5.0) <= 2 / 300      # the rest, to a sample
    assert [c["trial"] for c in ses["coast_friction"]] == [t["name"] for t in ses["trials"]]
    assert "## Session" in (out / "report.md").read_text()
