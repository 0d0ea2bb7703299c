//! FRF CSV reader (`host-tools/src/io/frf_csv.rs`), direct `<a>_` and matrix
//! `<i><j>_` columns: arbitrary bytes never panic; an accepted FRF is
//! writable and reads back equal (write → read); its matrix status agrees
//! with its entries; a rejected input's error names the file and a place in it.
#![no_main]

use dynocomp::frf::{Frf, MatrixKind};
use dynocomp::io::frf_csv::{frf_csv_to_string, parse_frf_csv, parse_frf_csv_bytes};
use dynocomp_fuzz::assert_names_place;
use libfuzzer_sys::fuzz_target;

const SOURCE: &str = "fuzz.csv";

/// The matrix status, `entry` and `matrix_at` tell the same story.
fn check_matrix(frf: &Frf) {
    let st = frf.matrix_status();
    let n = frf.entries().count();
    assert_eq!(st.missing().len(), 9 - n);
    assert_eq!(frf.has_cross(), st.kind() != MatrixKind::DirectOnly);
    assert_eq!(frf.matrix_at(0).is_some(), n == 9);
    assert_eq!(st.message().is_none(), n == 9);
    for e in frf.entries() {
        assert_eq!(e.frf.len(), frf.freq_hz.len());
        assert!(st.present[e.channel][e.direction]);
    }
}

fuzz_target!(|data: &[u8]| {
    match parse_frf_csv_bytes(data, SOURCE) {
        Ok(frf) => {
            check_matrix(&frf);
            let text = frf_csv_to_string(&frf).expect("an accepted FRF is writable");
            let back = parse_frf_csv(&text, "roundtrip.csv").expect("written FRF CSV reads back");
            assert_eq!(back, frf, "FRF CSV write → read changed the FRF");
        }
        Err(e) => assert_names_place(&format!("{e:#}"), SOURCE),
    }
});
