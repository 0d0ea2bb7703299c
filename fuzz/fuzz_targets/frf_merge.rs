//! One FRF matrix from several files (`host-tools/src/io/frf_set.rs`): the
//! input is up to three files, FRF CSV or UFF 58, separated by the byte 0x1E
//! (the first byte's bits 0-2 say which are UFF). Every file is parsed as
//! `read_frf_set` parses it; a file refused alone names itself and a place
//! in it; a merge refused names one of the files and what is wrong (entry,
//! lines, units); an accepted merge holds exactly the entries of its files,
//! on the first file's lines, and writes and reads back as FRF CSV.
#![no_main]

use std::path::Path;

use dynocomp::io::frf_csv::{frf_csv_to_string, parse_frf_csv};
use dynocomp::io::frf_set::{merge_frf_files, parse_frf_file};
use dynocomp_fuzz::{assert_names_place, assert_names_place_or};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let mut files = Vec::new();
    for (k, part) in rest.split(|&b| b == 0x1e).take(3).enumerate() {
        let ext = if mode & (1 << k) != 0 { "uff" } else { "csv" };
        let name = format!("h{k}.{ext}");
        match parse_frf_file(Path::new(&name), part) {
            Ok(f) => files.push(f),
            Err(e) => {
                assert_names_place(&format!("{e:#}"), &name);
                return;
            }
        }
    }
    match merge_frf_files(&files) {
        Ok(merged) => {
            assert_eq!(merged.freq_hz, files[0].frf.freq_hz);
            let total: usize = files.iter().map(|f| f.frf.entries().count()).sum();
            assert_eq!(merged.entries().count(), total, "entries lost or invented");
            for f in &files {
                for e in f.frf.entries() {
                    assert_eq!(merged.entry(e.channel, e.direction), Some(e), "entry changed by the merge");
                }
            }
            let text = frf_csv_to_string(&merged).expect("a merged FRF is writable");
            let back = parse_frf_csv(&text, "merged.csv").expect("the merged FRF reads back");
            assert_eq!(back, merged);
        }
        Err(e) => {
            let msg = format!("{e:#}");
            let source = files.iter().map(|f| f.source.as_str()).find(|s| msg.starts_with(&format!("{s}:")));
            let source = source.unwrap_or_else(|| panic!("merge error names none of the files: {msg}"));
            assert_names_place_or(&msg, source, &["entry", "lines", "units"]);
        }
    }
});
