"""The pre-start check of a run (uam_sim.preflight): node parameters against the nodes' own
tables, input files through the libraries' loaders, each refusal naming the flag or file, the
parameter and the value."""

from __future__ import annotations

import pathlib

from uam_sim.runner.preflight import flag_of, main

ROOT = pathlib.Path(__file__).resolve().parents[3]
NET = str(ROOT / "config" / "networks" / "tiny.yaml")


def _run(capsys, *argv):
    rc = main(["--prog", "run_fleet", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_good_values_pass_and_print_the_networks_separation_model(capsys):
    rc, out, err = _run(capsys, "--network", NET, "--node", "simulator", "--params-file",
                        str(ROOT / "config" / "simulator.yaml"), "-p", "duration_s:=600", "-p", "speed_error:=0.1")
    assert (rc, out.strip(), err) == (0, "sphere", "")


def test_a_flag_value_is_refused_naming_the_flag_parameter_and_value(capsys):
    rc, _, err = _run(capsys, "--node", "simulator", "-p", "speed_error:=2.0")
    assert rc == 2 and err.strip() == ("run_fleet: --speed-error (simulator parameter speed_error): 2.0 is above "
                                       "the maximum 0.79")
    assert flag_of("real_time_factor") == "--rtf" and flag_of("wind_speed_mps") == "--wind"


def test_a_params_file_value_and_an_unknown_name_are_refused_naming_the_file(tmp_path, capsys):
    cfg = tmp_path / "sim.yaml"
    cfg.write_text("simulator:\n  ros__parameters:\n    step_s: 0.0\n")
    rc, _, err = _run(capsys, "--node", "simulator", "--params-file", str(cfg))
    assert rc == 2 and f"simulator parameter step_s ({cfg}): 0.0 is below the minimum 0.001" in err
    cfg.write_text("simulator:\n  ros__parameters:\n    speed_eror: 0.1\n")
    rc, _, err = _run(capsys, "--node", "simulator", "--params-file", str(cfg))
    assert rc == 2 and "simulator has no parameter 'speed_eror'" in err


def test_files_are_loaded_by_the_libraries_loaders(tmp_path, capsys):
    bad = tmp_path / "c.geojson"
    bad.write_text("# not JSON\n")
    rc, _, err = _run(capsys, "--network", NET, "--constraints", str(bad))
    assert rc == 2 and f"run_fleet: --constraints: constraints file {str(bad)!r}: is not JSON" in err
    rc, _, err = _run(capsys, "--network", str(tmp_path / "none.yaml"))
    assert rc == 2 and err.startswith("run_fleet: --network: ")
