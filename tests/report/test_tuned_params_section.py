"""The report's lines for a MAVLink run: tuned parameters with their ±, the parameter files, the range edges."""

from __future__ import annotations

from mavtune.report.run_report import tuned_params_section


def test_lists_each_vehicles_parameters_files_and_edges():
    summary = {"tuned_params": {"tcp:a": {"PSC_POSZ_P": 2.625, "PSC_VELZ_P": 6.6875}},
               "tuned_params_tolerance": {"tcp:a": {"PSC_POSZ_P": 0.5, "PSC_VELZ_P": 1.75}},
               "param_files": ["tuned.parm", "tuned.params"],
               "range_edges": [{"message": "kd = 0.812 lies within ... PSC_VELZ_P ..."}]}
    text = "\n".join(tuned_params_section(summary))
    assert "| `tcp:a` | `PSC_POSZ_P` | 2.625 | ± 0.5 |" in text and "`PSC_VELZ_P` | 6.688 | ± 1.8 |" in text
    assert "`tuned.parm`" in text and "QGroundControl" in text
    assert "## Range edges" in text and "- kd = 0.812" in text


def test_a_log_scale_parameters_tolerance_is_the_values_it_spans_not_a_plus_minus():
    summary = {"tuned_params": {"m0": {"PSC_POSZ_P": 2.0, "PSC_VELZ_P": 8.0}},
               "tuned_params_tolerance": {"m0": {"PSC_POSZ_P": 0.4, "PSC_VELZ_P": 3.33}},
               "tuned_params_band": {"m0": {"PSC_VELZ_P": [5.278, 8.0]}}}
    text = "\n".join(tuned_params_section(summary))
    assert "`PSC_POSZ_P` | 2 | ± 0.4 |" in text and "`PSC_VELZ_P` | 8 | 5.28 – 8 |" in text and "not a ±" in text


def test_says_whose_file_is_whose_when_each_vehicle_has_its_own():
    summary = {"tuned_params": {"m0": {"PSC_POSZ_P": 2.0}, "m1": {"MPC_Z_P": 0.8}},
               "param_files": ["tuned-1.parm", "tuned-2.parm"],
               "param_file_vehicles": {"tuned-1.parm": ["m0"], "tuned-2.parm": ["m1"]}}
    text = "\n".join(tuned_params_section(summary))
    assert "`tuned-1.parm` (m0), `tuned-2.parm` (m1)" in text and "| `m1` | `MPC_Z_P` | 0.8 |" in text


def test_says_nothing_for_a_simulated_run_without_edges():
    assert tuned_params_section({"range_edges": []}) == []
