//! FRF CSV reader (`host-tools/src/io/frf_csv.rs`): arbitrary bytes never
//! panic; an accepted FRF is writable and reads back equal (write → read);
//! a rejected input's error names the file and a place in it.
#![no_main]

use dynocomp::io::frf_csv::{frf_csv_to_string, parse_frf_csv, parse_frf_csv_bytes};
use dynocomp_fuzz::assert_names_place;
use libfuzzer_sys::fuzz_target;

const SOURCE: &str = "fuzz.csv";

fuzz_target!(|data: &[u8]| {
    match parse_frf_csv_bytes(data, SOURCE) {
        Ok(frf) => {
            let text = frf_csv_to_string(&frf).expect("an accepted FRF is writable");
            let back = parse_frf_csv(&text, "roundtrip.csv").expect("written FRF CSV reads back");
            assert_eq!(back, frf, "FRF CSV write → read changed the FRF");
        }
        Err(e) => assert_names_place(&format!("{e:#}"), SOURCE),
    }
});
