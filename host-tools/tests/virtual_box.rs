//! `dynocomp flash --serial` and `dynocomp stream` against the virtual box
//! (`dynocomp virtual-box`: the box's own protocol handler, store and sample
//! function on a pseudo-terminal, with its simulated flash in a file):
//! upload and switch, restart, rejection of bad images, power cut in the
//! middle of an upload, malformed frames, stream with injected frame loss.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use dynocomp::link::flash_serial::upload;
use dynocomp::link::serial::Link;
use dynocomp::link::stream::record;
use dynocomp::link::virtual_box::{spawn, POWER_CUT_EXIT};
use dynocomp_core::image::CRC32;
use dynocomp_core::protocol::{encode_frame, FrameError, LinkError, Reply, Request, RequestFrame, MAX_FRAME};
use dynocomp_core::sample::BypassReason;
use dynocomp_core::shell::Slot;

const EXE: &str = env!("CARGO_BIN_EXE_dynocomp");

/// A running virtual box, killed on drop.
struct VBox {
    child: Child,
    pty: String,
}

impl VBox {
    fn start(flash: &Path, extra: &[&str]) -> VBox {
        let mut args = vec!["--flash", flash.to_str().unwrap()];
        args.extend_from_slice(extra);
        let (child, pty) = spawn(Path::new(EXE), &args).expect("virtual box starts");
        VBox { child, pty }
    }
    fn link(&self) -> Link {
        Link::open(&self.pty).expect("open pty")
    }
}

impl Drop for VBox {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn flash_cli(image: &Path, pty: &str) -> std::process::Output {
    Command::new(EXE).args(["flash", image.to_str().unwrap(), "--serial", pty]).output().unwrap()
}

#[test]
fn upload_switches_at_once_and_survives_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    let (one, two) = (common::good(1), common::good(2));
    let (p1, p2) = (write(dir.path(), "one.dcimg", &one), write(dir.path(), "two.dcimg", &two));
    {
        let vbox = VBox::start(&flash, &[]);
        let mut link = vbox.link();
        let s = link.status().unwrap();
        assert_eq!(s.bypass, Some(BypassReason::NoImage));
        assert_eq!(s.image, None);
        drop(link);

        let out = flash_cli(&p1, &vbox.pty);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let out = flash_cli(&p2, &vbox.pty);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        assert!(err.contains(&format!("switched to image {:#010x}", common::id(&two))), "{err}");

        // Running without a reboot: the new image is active and running.
        let s = vbox.link().status().unwrap();
        assert_eq!(s.bypass, None);
        assert_eq!(s.image.map(|i| i.id), Some(common::id(&two)));
        let a = s.active.unwrap();
        assert_eq!((a.slot, a.seq), (Slot::B, 2));
    }
    // Restart from the flash file: the newest slot wins.
    let vbox = VBox::start(&flash, &[]);
    let s = vbox.link().status().unwrap();
    assert_eq!(s.image.map(|i| i.id), Some(common::id(&two)));
    assert_eq!(s.active.map(|a| a.seq), Some(2));
}

#[test]
fn the_box_rejects_bad_images_and_keeps_running_the_old_one() {
    let dir = tempfile::tempdir().unwrap();
    let vbox = VBox::start(&dir.path().join("flash.bin"), &[]);
    let old = common::good(1);
    let mut link = vbox.link();
    upload(&mut link, &old, |_, _| {}).unwrap();

    // The box's own checks (the host's local check is bypassed here).
    for (bad, want) in [
        (common::offline_only(), "cannot run this image: the image is offline-only"),
        (common::slow(), "cannot run this image: sample rate 5000 Hz outside the box's"),
        (common::over_budget(), "cannot run this image: predicted CPU load "),
        (common::unstable(), "pole on or outside the unit circle"),
    ] {
        let err = upload(&mut link, &bad, |_, _| {}).unwrap_err().to_string();
        assert!(err.contains(want), "{err}");
        let s = link.status().unwrap();
        assert_eq!(s.image.map(|i| i.id), Some(common::id(&old)));
        assert_eq!(s.bypass, None);
    }

    // Corrupted in transfer: CRC declared for the good bytes, one byte flipped.
    let new = common::good(2);
    let mut sent = new.clone();
    sent[300] ^= 0x04;
    link.command(Request::UploadBegin { len: new.len() as u32, crc: CRC32.checksum(&new) }).unwrap();
    for (i, c) in sent.chunks(128).enumerate() {
        link.command(Request::UploadChunk { offset: (i * 128) as u32, bytes: c }).unwrap();
    }
    match link.request(Request::UploadCommit).unwrap() {
        Reply::Error(LinkError::CrcMismatch { declared, .. }) => assert_eq!(declared, CRC32.checksum(&new)),
        other => panic!("expected a CRC mismatch, got {other:?}"),
    }
    assert_eq!(link.status().unwrap().image.map(|i| i.id), Some(common::id(&old)));
    drop(link);

    // The CLI refuses a corrupted file before touching the box.
    let mut file = new.clone();
    file[200] ^= 0x01;
    let p = write(dir.path(), "bad.dcimg", &file);
    let out = flash_cli(&p, &vbox.pty);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("bad.dcimg") && (err.contains("BadCrc") || err.contains("CRC mismatch")), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");

    // ... and an offline-only or over-budget file, with the reason.
    for (name, bytes, want) in [
        ("offline.dcimg", common::offline_only(), "offline-only image"),
        ("heavy.dcimg", common::over_budget(), "exceeds the box's limit of 60 %"),
    ] {
        let p = write(dir.path(), name, &bytes);
        let out = flash_cli(&p, &vbox.pty);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{name}: {err}");
        assert!(err.contains(name) && err.contains(want), "{err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // Negative control: the good image of the same shape at 51.2 kHz flashes.
    let p = write(dir.path(), "good.dcimg", &common::good(7));
    let out = flash_cli(&p, &vbox.pty);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn power_cut_mid_upload_then_restart_runs_the_old_image() {
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    let (one, two) = (common::good(1), common::good(2));
    let p2 = write(dir.path(), "two.dcimg", &two);
    {
        let vbox = VBox::start(&flash, &[]);
        upload(&mut vbox.link(), &one, |_, _| {}).unwrap();
    }
    // Ops 0..4 erase slot B, 4.. write the image: cut in the middle of it.
    let mut vbox = VBox::start(&flash, &["--power-cut-at-op", "40"]);
    let out = flash_cli(&p2, &vbox.pty);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("no reply") || err.contains("box unplugged or stopped"), "{err}");
    assert_eq!(vbox.child.wait().unwrap().code(), Some(POWER_CUT_EXIT));
    drop(vbox);

    let vbox = VBox::start(&flash, &[]);
    let s = vbox.link().status().unwrap();
    assert_eq!(s.image.map(|i| i.id), Some(common::id(&one)));
    assert_eq!(s.bypass, None);
    // And the interrupted upload can be redone.
    let out = flash_cli(&p2, &vbox.pty);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(vbox.link().status().unwrap().image.map(|i| i.id), Some(common::id(&two)));
}

#[test]
fn malformed_truncated_and_out_of_order_frames_get_error_replies() {
    let dir = tempfile::tempdir().unwrap();
    let vbox = VBox::start(&dir.path().join("flash.bin"), &[]);
    let mut link = vbox.link();
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_frame(&RequestFrame { id: 77, request: Request::GetStatus }, &mut buf).unwrap();
    // Truncated: the first half of a frame, then a delimiter.
    link.send_raw(&buf[..n / 2]).unwrap();
    link.send_raw(&[0]).unwrap();
    // Oversized garbage.
    link.send_raw(&vec![0x55u8; 2 * MAX_FRAME]).unwrap();
    link.send_raw(&[0]).unwrap();
    // The link still works, and both bad frames were answered with errors.
    link.status().unwrap();
    assert_eq!(link.unreadable_replies.len(), 2, "{:?}", link.unreadable_replies);
    assert!(matches!(
        link.unreadable_replies[0],
        LinkError::Frame(FrameError::BadCrc | FrameError::Cobs | FrameError::Truncated)
    ));
    assert_eq!(link.unreadable_replies[1], LinkError::Frame(FrameError::Oversized));

    // Out-of-order chunk.
    let img = common::good(3);
    link.command(Request::UploadBegin { len: img.len() as u32, crc: CRC32.checksum(&img) }).unwrap();
    link.command(Request::UploadChunk { offset: 0, bytes: &img[..64] }).unwrap();
    match link.request(Request::UploadChunk { offset: 128, bytes: &img[128..192] }).unwrap() {
        Reply::Error(LinkError::OutOfOrder { expected: 64, got: 128 }) => {}
        other => panic!("{other:?}"),
    }
    // Commit too early.
    match link.request(Request::UploadCommit).unwrap() {
        Reply::Error(LinkError::Incomplete { received: 64, .. }) => {}
        other => panic!("{other:?}"),
    }
    // Bypass on/off is acknowledged and visible in the status.
    link.command(Request::SetBypass(true)).unwrap();
    assert_eq!(link.status().unwrap().bypass, Some(BypassReason::NoImage));
}

#[test]
fn stream_reports_exactly_the_injected_frame_losses() {
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    let one = common::good(1);
    {
        let vbox = VBox::start(&flash, &[]);
        upload(&mut vbox.link(), &one, |_, _| {}).unwrap();
    }
    let vbox = VBox::start(&flash, &["--drop-frames", "3,10,11"]);
    let out = dir.path().join("rec.csv");
    let mut link = vbox.link();
    let report = record(&mut link, Some(1), &out, Some(400), |n, _| n >= 400).unwrap();
    assert_eq!(report.lost_frames, 3, "{report:?}");
    assert_eq!(report.lost_ranges, vec![(3, 3), (10, 11)]);
    assert_eq!(report.index_gaps, 0);
    assert_eq!(report.samples, 400);
    // The virtual box has no CPU cycles to count and misses no deadlines.
    assert_eq!(
        report.box_load,
        dynocomp::link::stream::BoxLoad {
            fs_hz: 51_200,
            core_clock_hz: 0,
            overruns: 0,
            overruns_since_boot: 0,
            isr_cycles_mean: 0,
            isr_cycles_max: 0
        }
    );

    // The CSV: header, 400 rows, raw forces equal the virtual box's
    // synthetic input (2048 + 900 sin(2π·50·k/fs) codes on x, scaled by
    // 0.5 N/code), and exactly 3 × 8 samples missing in t_s.
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t_s,fx,fy,fz,raw_fx,raw_fy,raw_fz"));
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 400);
    let fs = 51_200.0;
    let mut missing = 0.0;
    for w in rows.windows(2) {
        missing += ((w[1][0] - w[0][0]) * fs).round() - 1.0;
    }
    assert_eq!(missing, 24.0);
    // t_s is the box's sample index / fs: the raw columns must be exactly
    // the synthetic input at that index, in newtons (0.5·(i+1) N/code).
    for r in &rows {
        let k = (r[0] * fs).round();
        for (i, col) in [4, 5, 6].into_iter().enumerate() {
            let f = 50.0 * (i as f64 + 1.0);
            let code = (2048.0 + 900.0 * (2.0 * std::f64::consts::PI * f * k / fs).sin()).round();
            let want = (code - 2048.0) * 0.5 * (i as f64 + 1.0);
            assert!((r[col] - want).abs() < 1e-9, "t_s {} axis {i}: {} vs {want}", r[0], r[col]);
        }
        assert!(r[1..4].iter().all(|v| v.is_finite()));
    }
    drop(link);

    // The CLI prints the same report on one line.
    let vbox2 = VBox::start(&flash, &["--drop-frames", "2"]);
    let csv = dir.path().join("cli.csv");
    let o = Command::new(EXE)
        .args([
            "stream",
            "--serial",
            &vbox2.pty,
            "--output",
            csv.to_str().unwrap(),
            "--samples",
            "200",
            "--decimation",
            "2",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("200 samples") && err.contains("lost frames: 1 (seq 2)"), "{err}");
    // ... then the box's overruns and interrupt cost (not measured here).
    assert!(err.contains("box: overruns (missed sample deadlines): 0 during this recording, 0 since boot"), "{err}");
    assert!(err.contains("sample interrupt: cycle count not measured"), "{err}");
    assert!(!err.contains("WARNING"), "{err}");
    // The recording is a valid signal CSV for `dynocomp compensate`.
    let rec = dynocomp::io::signal_csv::read_signal_csv(&csv).unwrap();
    let text = std::fs::read_to_string(&csv).unwrap();
    let fx: Vec<f64> = text.lines().skip(1).map(|l| l.split(',').nth(1).unwrap().parse().unwrap()).collect();
    assert_eq!(rec.channel(0), Some(&fx[..]), "the reader takes fx, not raw_fx");
    assert_eq!(rec.len(), 200);
}

/// A port another program holds for a moment (ModemManager probing a new
/// USB CDC device, a previous `dynocomp` still closing) is waited for; one
/// held longer than `PORT_BUSY_WAIT` is refused with a message saying so.
#[test]
fn a_busy_port_is_waited_for_then_refused_with_a_reason() {
    use dynocomp::link::serial::{open_port, PORT_BUSY_WAIT};
    use serialport::SerialPort;
    let (_master, slave) = serialport::TTYPort::pair().unwrap();
    let path = slave.name().unwrap();
    drop(slave);
    let keep = std::fs::OpenOptions::new().read(true).write(true).open(&path).unwrap();
    // held 300 ms by another opener (an exclusive flock, as serialport takes)
    let holder = serialport::new(&path, 115_200).open().unwrap();
    let release = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(300));
        drop(holder);
    });
    let t = std::time::Instant::now();
    let port = open_port(&path);
    assert!(port.is_ok(), "{:#}", port.err().unwrap());
    assert!(t.elapsed() >= std::time::Duration::from_millis(250), "opened while held");
    release.join().unwrap();
    drop(port);
    // held throughout: refused after the wait, naming the port and why
    let _holder = serialport::new(&path, 115_200).open().unwrap();
    let e = format!("{:#}", open_port(&path).err().expect("a held port must be refused"));
    assert!(e.contains(&path) && e.contains("busy for") && !e.contains('\n'), "{e}");
    let _ = (keep, PORT_BUSY_WAIT);
}
