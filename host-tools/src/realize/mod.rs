//! Realize: turn a linear filter into the box's f32 modal form and prove it.
//!
//! [`modal`] realizes a state-space compensator as 2x2 "delta" blocks plus
//! an FIR tail, [`quantize`] rounds it to f32 and verifies it against the
//! f64 filter, [`load`] predicts the box's CPU load of an image.
//! May import only the leaves (frf, metrics, numeric, io, fit) and the core.

// `!(x < limit)` on purpose throughout: a NaN residual, condition number or
// error must fail the check, which `x >= limit` would let pass.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod choose;
pub mod image;
pub mod load;
pub mod mimo;
pub mod modal;
pub mod quantize;

/// A refusal by the box's image check (`dynocomp_core::image`), in the
/// design's terms: the box's wording blames a corrupted image, which a
/// filter the design has just made is not; the check and its figures stay.
pub(crate) fn image_check_refusal(e: &dynocomp_core::image::ImageError) -> String {
    let mut s = e.to_string();
    let kept = ["(image corrupted or not a force compensator)", "(image corrupted)", ": image corrupted or unstable"]
        .iter()
        .find_map(|tail| s.strip_suffix(tail))
        .map(|t| t.trim_end().len());
    if let Some(n) = kept {
        s.truncate(n);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynocomp_core::image::ImageError;

    /// The box's wording ("image corrupted") is left out of a design's
    /// refusal, and the figures kept; the box's own messages (the control)
    /// still say it.
    #[test]
    fn an_image_check_refusal_does_not_blame_a_corrupted_image() {
        for e in [
            ImageError::GainBoundTooLarge { axis: 0, bound: 5000 },
            ImageError::CoefficientOutOfRange { axis: 0, section: 255 },
            ImageError::CoefficientOutOfRange { axis: 0, section: 2 },
            ImageError::TapOutOfRange { axis: 0, tap: 3 },
            ImageError::MatrixGainBoundTooLarge { row: 1, bound: 5000 },
            ImageError::MatrixCoefficientOutOfRange { section: 4 },
        ] {
            let (boxed, designed) = (e.to_string(), image_check_refusal(&e));
            assert!(boxed.contains("corrupted"), "{boxed}");
            assert!(!designed.contains("corrupted") && boxed.starts_with(&designed), "{designed}");
        }
        let e = ImageError::GainBoundTooLarge { axis: 0, bound: 5000 };
        assert!(image_check_refusal(&e).ends_with("up to 5000 times (limit 1e4)"), "{}", image_check_refusal(&e));
        let e = ImageError::MatrixDcGainOutOfRange { row: 0 };
        assert_eq!(image_check_refusal(&e), e.to_string());
    }
}
