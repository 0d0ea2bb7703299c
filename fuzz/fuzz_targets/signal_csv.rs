//! Signal CSV reader (`host-tools/src/io/signal_csv.rs`): arbitrary text
//! never panics; an accepted record written with `write_signal_csv` (path
//! only: a scratch file in /dev/shm) reads back equal; a rejected input's
//! error names the file and a place in it.
//!
//! The UFF58 time-history and TDMS signal readers (issue #14) get a target
//! of the same shape: parse, write → read if a writer exists, else
//! `assert_names_place`.
#![no_main]

use dynocomp::io::signal_csv::{parse_signal_csv, read_signal_csv, write_signal_csv};
use dynocomp_fuzz::{assert_names_place, scratch_path};
use libfuzzer_sys::fuzz_target;

const SOURCE: &str = "fuzz.csv";

fuzz_target!(|data: &[u8]| {
    // The reader takes text (`read_to_string` refuses non-UTF-8 first).
    let Ok(text) = std::str::from_utf8(data) else { return };
    match parse_signal_csv(text, SOURCE) {
        Ok(rec) => {
            let path = scratch_path("signal.csv");
            write_signal_csv(&path, &rec).expect("an accepted record is writable");
            let back = read_signal_csv(&path).expect("a written record reads back");
            let _ = std::fs::remove_file(&path);
            assert_eq!(back, rec, "signal CSV write → read changed the record");
        }
        Err(e) => assert_names_place(&format!("{e:#}"), SOURCE),
    }
});
