//! The box with a 3x3 image (format version 3): the sample path against an
//! independent computation (the documented scaling around
//! `MimoFilter::step`), the runaway guard, the mode rules (offline-only,
//! CPU budget, user bypass), and the route of an upload through the USB
//! request handler and the coefficient store to the sample path.

mod common;
use common::*;

use dynocomp_core::budget::{image_load, BOX_LOAD_LIMIT_PERMILLE};
use dynocomp_core::image::*;
use dynocomp_core::link::{Actions, BoxLink, Telemetry};
use dynocomp_core::mimo::MimoState;
use dynocomp_core::protocol::{LinkError, Reply, Request, StatusCounters, MAX_CHUNK};
use dynocomp_core::sample::*;
use dynocomp_core::shell::{ActiveImage, SamplePath};
use dynocomp_core::store::{Layout, Store};
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// 10 pairs + 8 taps fits the budget at 25.6 kHz; 40 pairs + 24 taps does
/// not fit at 51.2 kHz.
fn small(fs: u32) -> MatrixImage {
    matrix_image(mimo_test_filter(f64::from(fs), 10, 0, 8, 0xAB), fs)
}

fn codes(k: u32) -> [u16; 3] {
    let c = |a: u32| (2048 + ((k * 37 + a * 1009) % 401) as i32 - 200) as u16;
    [c(0), c(1), c(2)]
}

#[test]
fn the_3x3_path_scales_filters_and_scales_back() {
    let img = small(25_600);
    let boxed = BoxImage::Matrix(img);
    let loaded = Ok(boxed);
    let mode = select_mode(Some(&loaded), false);
    assert!(matches!(mode, Mode::Compensate(BoxImage::Matrix(_))), "{mode:?}");
    let mut st = SampleState::default();
    let mut truth_state = MimoState::default();
    for k in 0..2_000 {
        let c = codes(k);
        let (dac, flags) = process_sample(c, mode, &mut st);
        // Truth: the documented equations, written out here.
        let u: [f32; 3] = core::array::from_fn(|i| {
            (f32::from(c[i]) - img.axes[i].scaling.adc_offset_code) * img.axes[i].scaling.newton_per_code
        });
        let y = img.filter.step(&mut truth_state, u);
        let want: [u16; 3] = core::array::from_fn(|i| {
            let v = img.axes[i].scaling.dac_offset_code + y[i] * img.axes[i].scaling.dac_code_per_newton;
            v.round().clamp(0.0, 4095.0) as u16
        });
        for i in 0..3 {
            // to_dac_code rounds half up; f32::round rounds half away from
            // zero: the same for the non-negative codes here.
            assert_eq!(dac[i], want[i], "sample {k} axis {i}");
        }
        assert_eq!(flags, SampleFlags(0));
    }
    assert_eq!(st.matrix, truth_state);
    // A force on x alone moves the y and z outputs (crosstalk compensated),
    // which a per-axis image never does.
    let mut st = SampleState::default();
    let mut moved = [false; 3];
    for k in 0..50 {
        let x = if k == 0 { 2448 } else { 2048 };
        let (dac, _) = process_sample([x, 2048, 2048], mode, &mut st);
        for i in 1..3 {
            moved[i] |= dac[i] != 2048;
        }
    }
    assert!(moved[1] && moved[2], "{moved:?}");
}

#[test]
fn a_3x3_runaway_resets_all_axes_counts_once_and_outputs_raw_forces() {
    let loaded = Ok(BoxImage::Matrix(small(25_600)));
    let mode = select_mode(Some(&loaded), false);
    let mut st = SampleState::default();
    for k in 0..10 {
        process_sample(codes(k), mode, &mut st);
    }
    st.matrix.x[3][1] = f32::NAN;
    let (dac, flags) = process_sample([2148, 1948, 2048], mode, &mut st);
    for i in 0..3 {
        assert!(flags.has(SampleFlags::reset(i)), "axis {i} not flagged");
    }
    // Raw forces out: (code − 2048)·2.5 N → 2048 + 0.4·force = the code.
    assert_eq!(dac, [2148, 1948, 2048]);
    assert_eq!(st.matrix.nonfinite_resets, 1);
    assert_eq!(st.nonfinite_resets(), [1, 1, 1]);
    assert!(st.matrix.x.iter().flatten().chain(st.matrix.hist.iter().flatten()).all(|v| *v == 0.0));
    // Negative control: the next sample runs normally again.
    let (_, flags) = process_sample(codes(11), mode, &mut st);
    assert_eq!(flags, SampleFlags(0));
}

#[test]
fn offline_only_over_budget_and_user_bypass_3x3_images_are_not_run() {
    let mut offline = small(25_600);
    offline.flags = FLAG_OFFLINE_ONLY;
    assert!(matches!(select_mode(Some(&Ok(offline.into())), false), Mode::Bypass(BypassReason::OfflineOnly)));
    let big = matrix_image(mimo_test_filter(51_200.0, 40, 0, 24, 3), 51_200);
    let load = image_load(&big);
    assert!(load.permille > BOX_LOAD_LIMIT_PERMILLE, "{load:?}");
    let loaded = Ok(big.into());
    let mode = select_mode(Some(&loaded), false);
    assert!(matches!(mode, Mode::Bypass(BypassReason::OverBudget(l)) if l == load), "{mode:?}");
    let mut st = SampleState::default();
    let (dac, flags) = process_sample([100, 2048, 4000], mode, &mut st);
    assert_eq!(dac, [100, 2048, 4000]);
    assert!(flags.has(SampleFlags::BYPASS));
    let fits = small(25_600);
    assert!(image_load(&fits).permille <= BOX_LOAD_LIMIT_PERMILLE, "{:?}", image_load(&fits));
    assert!(matches!(select_mode(Some(&Ok(fits.into())), true), Mode::Bypass(BypassReason::User)));
    // Negative control: the same image without the user's bypass runs.
    assert!(matches!(select_mode(Some(&Ok(fits.into())), false), Mode::Compensate(_)));
}

#[test]
fn switching_between_per_axis_and_3x3_images_starts_from_rest() {
    let per_axis: BoxImage =
        image_with(dynocomp_core::kernel::AxisFilter::gain(1.0).unwrap(), &[0, 1, 2], 25_600).into();
    let matrix: BoxImage = small(25_600).into();
    let mut path = SamplePath::new();
    let mut active = ActiveImage::new(Ok(matrix));
    let first: Vec<_> = (0..100).map(|k| path.tick(codes(k), &mut active, false).dac).collect();
    active = ActiveImage::new(Ok(per_axis));
    path.on_image_switch();
    let out = path.tick(codes(100), &mut active, false);
    assert_eq!(out.dac, codes(100), "gain-1 per-axis image: codes out");
    active = ActiveImage::new(Ok(matrix));
    path.on_image_switch();
    let again: Vec<_> = (0..100).map(|k| path.tick(codes(k), &mut active, false).dac).collect();
    assert_eq!(first, again, "the 3x3 state restarts from rest");
}

// ------------------------------------------------ upload through the link --

/// A NOR flash in RAM with the G474's geometry (8-byte writes, 2 KiB pages).
struct RamFlash(Vec<u8>);

#[derive(Debug)]
struct RamError;
impl NorFlashError for RamError {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::Other
    }
}
impl ErrorType for RamFlash {
    type Error = RamError;
}
impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamError> {
        let o = offset as usize;
        bytes.copy_from_slice(self.0.get(o..o + bytes.len()).ok_or(RamError)?);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.0.len()
    }
}
impl NorFlash for RamFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = 2048;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), RamError> {
        self.0.get_mut(from as usize..to as usize).ok_or(RamError)?.fill(0xFF);
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamError> {
        let o = offset as usize;
        for (d, s) in self.0.get_mut(o..o + bytes.len()).ok_or(RamError)?.iter_mut().zip(bytes) {
            *d &= *s;
        }
        Ok(())
    }
}

fn upload(link: &mut BoxLink, store: &mut Store<RamFlash>, bytes: &[u8]) -> (Reply, Actions) {
    let tel = Telemetry {
        firmware: [0, 1, 0],
        fs_hz: 25_600,
        core_clock_hz: 0,
        bypass: None,
        image: None,
        counters: StatusCounters::default(),
        stream_next_seq: 0,
    };
    let mut act = Actions::default();
    let crc = CRC32.checksum(bytes);
    assert_eq!(link.handle(Request::UploadBegin { len: bytes.len() as u32, crc }, store, &tel, &mut act), Reply::Ack);
    for (i, chunk) in bytes.chunks(MAX_CHUNK).enumerate() {
        let r =
            link.handle(Request::UploadChunk { offset: (i * MAX_CHUNK) as u32, bytes: chunk }, store, &tel, &mut act);
        assert_eq!(r, Reply::Ack);
    }
    let r = link.handle(Request::UploadCommit, store, &tel, &mut act);
    (r, act)
}

#[test]
fn a_3x3_image_is_uploaded_verified_committed_and_reported() {
    let layout = Layout { a: 0, b: 8192, len: 8192 };
    let mut store = Store::open(RamFlash(vec![0xFF; 16_384]), layout).unwrap();
    let mut link = BoxLink::new();
    let img = small(25_600);
    let (reply, act) = upload(&mut link, &mut store, &encode_matrix(&img));
    assert_eq!(reply, Reply::Ack);
    assert!(act.switch_image);
    let loaded = store.load_active().expect("the committed slot loads");
    assert_eq!(loaded, BoxImage::Matrix(img));
    assert_eq!(store.boot().image, Ok(BoxImage::Matrix(img)));
    assert_eq!(store.active().map(|a| a.image_id), Some(img.id()));
    // The status names the 3x3 image and its rows.
    let tel = Telemetry {
        firmware: [0, 1, 0],
        fs_hz: 25_600,
        core_clock_hz: 0,
        bypass: None,
        image: Some(&loaded),
        counters: StatusCounters::default(),
        stream_next_seq: 0,
    };
    match link.handle(Request::GetStatus, &mut store, &tel, &mut Actions::default()) {
        Reply::Status(s) => {
            let summary = s.image.expect("image summary");
            assert_eq!(summary.rows, Some(img.rows));
            assert_eq!(summary.id, img.id());
            assert!(summary.axes.iter().all(|a| a.is_some()));
        }
        r => panic!("{r:?}"),
    }
    // A per-axis image after it reports no rows.
    let v1: BoxImage = image_with(dynocomp_core::kernel::AxisFilter::gain(1.0).unwrap(), &[0], 25_600).into();
    let tel = Telemetry { image: Some(&v1), ..tel };
    match link.handle(Request::GetStatus, &mut store, &tel, &mut Actions::default()) {
        Reply::Status(s) => assert_eq!(s.image.and_then(|i| i.rows), None),
        r => panic!("{r:?}"),
    }
}

#[test]
fn a_3x3_image_over_budget_is_refused_and_the_running_one_stays() {
    let layout = Layout { a: 0, b: 8192, len: 8192 };
    let mut store = Store::open(RamFlash(vec![0xFF; 16_384]), layout).unwrap();
    let mut link = BoxLink::new();
    let good = small(25_600);
    assert_eq!(upload(&mut link, &mut store, &encode_matrix(&good)).0, Reply::Ack);
    let big = matrix_image(mimo_test_filter(51_200.0, 40, 0, 24, 3), 51_200);
    let (reply, act) = upload(&mut link, &mut store, &encode_matrix(&big));
    assert!(matches!(reply, Reply::Error(LinkError::NotRunnable(BypassReason::OverBudget(_)))), "{reply:?}");
    assert!(!act.switch_image);
    assert_eq!(store.boot().image, Ok(BoxImage::Matrix(good)));
}
