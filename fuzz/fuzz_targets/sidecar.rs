//! Model sidecar JSON (`host-tools/src/smoother.rs`, `parse_sidecar`, the
//! pure part of `read_sidecar`) checked against the project's example image.
//!
//! Checks: never panics, neither the parse nor the per-axis model check nor
//! building the smoother from an accepted model, nor the 3x3 model's check
//! and its smoother (a sidecar of a 3x3 image); an accepted sidecar
//! re-serialised reads back equal (write → read); a rejected one's error
//! names the file and the place (JSON line/column, or the field: format,
//! image id / source / rate).
#![no_main]

use std::path::Path;

use dynocomp::offline::sidecar::parse_sidecar;
use dynocomp::offline::matrix_smoother::MatrixSmoother;
use dynocomp::offline::smoother::Smoother;
use dynocomp_fuzz::{assert_names_place_or, example_image};
use libfuzzer_sys::fuzz_target;

const SOURCE: &str = "fuzz.dcimg.model.json";

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let image = example_image();
    let image_path = Path::new("fuzz.dcimg");
    match parse_sidecar(text, SOURCE, &image, image_path) {
        Ok(s) => {
            let again = serde_json::to_string(&s).expect("an accepted sidecar serialises");
            let back = parse_sidecar(&again, "again.json", &image, image_path).expect("a written sidecar reads back");
            assert_eq!(back, s, "sidecar write → read changed it");
            for axis in 0..dynocomp_core::AXES {
                // The continuous model's check, then the discrete model the
                // smoother runs on (stored, validated; or the FOH of the
                // continuous one for an older sidecar) and the smoother.
                match s.model(axis, SOURCE) {
                    Ok(model) if model.terms.len() <= 16 => match s.discrete_model(axis, SOURCE) {
                        Ok(dm) if dm.terms.len() <= 16 && dm.fir.len() <= 16 && dm.advance <= 16 => {
                            let _ = Smoother::new(&dm, 1.0, 0.05);
                        }
                        Ok(_) => {}
                        Err(e) => assert_names_place_or(&format!("{e:#}"), SOURCE, &["axis "]),
                    },
                    Ok(_) => {}
                    Err(e) => assert_names_place_or(&format!("{e:#}"), SOURCE, &["axis "]),
                }
            }
            if let Some(m) = s.matrix.as_ref().filter(|m| m.plant_a.len() <= 16) {
                match m.plant(s.fs_hz, SOURCE) {
                    Ok(plant) => {
                        let _ = MatrixSmoother::new(&plant, m.q, m.r, m.advance);
                    }
                    Err(e) => assert_names_place_or(&format!("{e:#}"), SOURCE, &["3x3 model"]),
                }
            }
        }
        Err(e) => assert_names_place_or(&format!("{e:#}"), SOURCE, &["format `", "belongs to image"]),
    }
});
