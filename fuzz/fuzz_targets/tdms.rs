//! NI TDMS signal reader (`host-tools/src/io/tdms.rs`): arbitrary bytes
//! never panic (path only: a scratch file in /dev/shm); an accepted record
//! written with `TdmsWriter` reads back bit for bit, with the same axes; a
//! rejected input's error names the file and a place in it (segment,
//! offset, channel) or the whole file.
#![no_main]

use dynocomp::io::signal::{read_all, SignalWriter};
use dynocomp::io::tdms::TdmsReader;
use dynocomp::io::tdms::TdmsWriter;
use dynocomp_fuzz::{assert_names_place_or, scratch_path};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = scratch_path("in.tdms");
    std::fs::write(&path, data).expect("scratch file");
    let source = path.display().to_string();
    let got = TdmsReader::open(&path, None).and_then(|mut r| {
        let axes = dynocomp::io::signal::SignalReader::axes(&r).to_vec();
        read_all(&mut r).map(|(_, c)| (axes, c))
    });
    let _ = std::fs::remove_file(&path);
    match got {
        Ok((axes, chans)) => {
            let mut bytes = Vec::new();
            {
                let mut w = TdmsWriter::new(&mut bytes, &axes, 51200.0, 0.0).expect("writer");
                let sl: Vec<&[f64]> = chans.iter().map(Vec::as_slice).collect();
                w.write_block(None, &sl).expect("an accepted record is writable");
                w.finish().expect("finish");
            }
            let out = scratch_path("out.tdms");
            std::fs::write(&out, &bytes).expect("scratch file");
            let mut r = TdmsReader::open(&out, None).expect("a written record reads back");
            assert_eq!(dynocomp::io::signal::SignalReader::axes(&r), axes.as_slice());
            let (_, back) = read_all(&mut r).expect("a written record reads back");
            let _ = std::fs::remove_file(&out);
            for (b, c) in back.iter().zip(&chans) {
                assert!(
                    b.len() == c.len() && b.iter().zip(c).all(|(x, y)| x.to_bits() == y.to_bits()),
                    "TDMS write → read changed the record"
                );
            }
        }
        Err(e) => assert_names_place_or(&format!("{e:#}"), &source, &["segment", "channel", "--channels"]),
    }
});
