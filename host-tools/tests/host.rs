//! The host-tools integration tests, one module per file of this folder, in
//! one test binary: one link instead of one per file, and one pool of test
//! threads for them all. `tests/mimo_design.rs` (release-only 3x3 designs)
//! stays a binary of its own.

mod cli_common;
mod common;
mod sim_common;

mod above_band_cli;
mod architecture;
mod budget_cli;
mod cli_robustness;
mod clipping_cli;
mod coherent_band;
mod compensate_stream;
mod design_progress;
mod design_units;
mod discretize;
mod drift_sim;
mod e2e_design;
mod e2e_rates;
mod fit_limits;
mod fit_uncertainty_cli;
mod flash_probe;
mod flat_force_cli;
mod force_prior;
mod force_spectrum;
mod freq_response;
mod help_text;
mod independent_cases;
mod io_frf;
mod io_frf_matrix;
mod latency_cli;
mod link_fuzz;
mod matrix_host;
mod metrics_as_written;
mod offline;
mod offline_cli;
mod paper_cli;
mod paper_findings;
mod paper_presets;
mod paper_units;
mod parallel_elaboration;
mod pass_through_cli;
mod phase_limit;
mod realize_scaling;
mod report;
mod riccati;
mod sensitivity;
mod sensitivity_cli;
mod signal_csv;
mod signal_plausible;
mod sim_plate;
mod sim_plate_cli;
mod simulate;
mod store_power_fail;
mod sweep_cases;
mod tail_lookahead;
mod tdms_signal;
mod two_state;
mod two_state_cli;
mod two_state_report;
mod uff_signal;
mod versus_default_cli;
mod virtual_box;

/// Every file of this folder is declared above (with autotests off, a file
/// left out would build and run nowhere), and nothing is declared that is
/// not a file here.
#[test]
fn every_test_file_is_a_module_of_this_binary() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let declared: std::collections::BTreeSet<String> = include_str!("host.rs")
        .lines()
        .filter_map(|l| l.strip_prefix("mod ")?.strip_suffix(';').map(str::to_string))
        .collect();
    let files: std::collections::BTreeSet<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "rs") || p.join("mod.rs").is_file())
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .filter(|n| n != "host" && n != "mimo_design")
        .collect();
    // The parse found the list (a control that the comparison is not of
    // two empty sets).
    assert!(declared.contains("two_state") && declared.contains("common"), "{declared:?}");
    let missing: Vec<_> = files.difference(&declared).collect();
    let stray: Vec<_> = declared.difference(&files).collect();
    assert!(missing.is_empty(), "test files not declared in tests/host.rs: {missing:?}");
    assert!(stray.is_empty(), "modules of tests/host.rs without a file: {stray:?}");
}
