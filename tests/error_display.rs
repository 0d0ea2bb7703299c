//! Every error the host prints has a one-line human message (Display),
//! not a Rust debug name: what `flash` showed as
//! `Image(BadCrc { stored: …, computed: … })`.

use dynocomp_core::budget::Load;
use dynocomp_core::image::ImageError;
use dynocomp_core::kernel::FilterError;
use dynocomp_core::protocol::{FlashFault, FrameError, LinkError};
use dynocomp_core::sample::BypassReason;
use dynocomp_core::shell::{AutoZeroError, Slot};
use dynocomp_core::store::{LayoutError, VerifyFailure};

/// One line, no debug names (a `{` or a CamelCase variant name).
fn human(s: &str) {
    assert!(!s.is_empty() && !s.contains('\n') && !s.contains('{'), "{s}");
    for debug in ["BadCrc", "Image(", "NotRunnable", "OverBudget", "Frame(", "NonFinite", "Saturated", "InvalidImage"] {
        assert!(!s.contains(debug), "debug name {debug} in: {s}");
    }
}

#[test]
fn core_errors_display_as_one_human_line() {
    let crc = ImageError::BadCrc { stored: 0x1234_5678, computed: 0x9abc_def0 };
    let e = LinkError::Image(crc).to_string();
    human(&e);
    assert!(e.contains("CRC mismatch") && e.contains("0x12345678") && e.contains("0x9abcdef0"), "{e}");
    let load = Load { cycles: 2100, permille: 632 };
    let cases = [
        LinkError::Frame(FrameError::BadCrc).to_string(),
        LinkError::NotRunnable(BypassReason::OverBudget(load)).to_string(),
        LinkError::NotRunnable(BypassReason::InvalidImage(ImageError::DcGainOutOfRange { axis: 2 })).to_string(),
        LinkError::Flash(FlashFault::Verify).to_string(),
        LinkError::UploadTooLarge { len: 9000, max: 8000 }.to_string(),
        BypassReason::UnsupportedSampleRate(5000).to_string(),
        FilterError::NonFinite(3).to_string(),
        FilterError::NonFinite(dynocomp_core::kernel::MAX_SECTIONS).to_string(),
        VerifyFailure::Crc { stored: 1, computed: 2 }.to_string(),
        VerifyFailure::NotRunnable(BypassReason::OfflineOnly).to_string(),
        LayoutError::Slots.to_string(),
        AutoZeroError::Saturated(1).to_string(),
        Slot::B.to_string(),
    ];
    for s in &cases {
        human(s);
    }
    assert!(cases[1].contains("63.2 %") && cases[1].contains("2100"), "{}", cases[1]);
    assert!(cases[7].contains("direct term"), "{}", cases[7]);
    assert!(cases[11].contains("axis y"), "{}", cases[11]);
    // Negative control: the debug form is what the check refuses.
    assert!(std::panic::catch_unwind(|| human(&format!("{:?}", LinkError::Image(crc)))).is_err());
}
