//! The core kernel on the target CPU: Cortex-M4F (thumbv7em-none-eabihf)
//! under `qemu-system-arm -M mps2-an386`, against the same kernel on the
//! host, bit for bit (issue #6).
//!
//! The test builds `qemu/` (the `kernel_io` program, which calls
//! `dynocomp_core::kernel::AxisFilter::step`, the one kernel), hands it a
//! coefficient image and a 3-axis input record through semihosting files,
//! and requires every output sample to have the same f32 bit pattern as the
//! host's. What could make them differ, and why it does not:
//!
//! * FMA contraction: rustc never contracts `a*b + c` into a fused
//!   multiply-add on its own (no `contract` fast-math flag); the M4 code may
//!   use `vmla.f32`, which is *not* fused (it rounds the product, ARMv7-M ARM
//!   instruction "VMLA, VMLS"), so it equals a separate multiply and add.
//! * x87 extended precision: x86-64 uses SSE scalar f32 arithmetic (IEEE
//!   binary32, round to nearest even), like the M4 FPU.
//! * Subnormals: the M4 FPU flushes them only with FPSCR.FZ = 1; the program
//!   reports FPSCR and the test requires FZ = DN = 0 and round-to-nearest
//!   (the reset value; neither cortex-m-rt nor the firmware changes it).
//!   The input ends in silence and axis z has only fast modes, so its
//!   output decays through the subnormal range and that path is compared
//!   too (with FZ = 1 the test fails there).
//!
//! If `qemu-system-arm` is missing the test FAILS and says how to install
//! it (`bash scripts/test.sh` does it).

mod common;
use common::*;

use dynocomp_core::image::CoeffImage;
use dynocomp_core::kernel::{AxisFilter, AxisState, Section};
use dynocomp_core::mimo::{MimoFilter, MimoState};
use dynocomp_core::AXES;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FS_HZ: f64 = 51_200.0;
/// Samples per axis: 0.6 s at 51.2 kHz.
const FRAMES: usize = 30_720;
/// Wall-clock limit of one emulator run.
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);

const INSTALL_HINT: &str = "install it with `apt-get install -y --no-install-recommends qemu-system-arm` \
     (Debian/Ubuntu), or run the README's test command `bash scripts/test.sh`, which does";

/// Three different 24-section + 24-tap filters: x and y with realistic
/// poles (100 Hz .. 22 kHz modes at 51.2 kHz, 1-5 % damping); z with only
/// fast, well-damped modes (2-22 kHz, 20-28 %), so that its output decays
/// through the subnormal range during the input's silent tail and a
/// flush-to-zero FPU would give different output bits. Axis y has 23 pairs
/// and a real pole (an odd pair count: the last-pair path of the M4's
/// assembly pair loop, `src/kernel_m4.rs`, then the real-pole loop); axis z
/// a diagonal section (two real poles after an even pair count). The axes
/// have 24, 23 and 5 FIR taps (every path of the assembly FIR loop).
fn test_image() -> CoeffImage {
    let (blocks, d) = filter_24(FS_HZ);
    let mut img = image_with(kernel_filter(&blocks, d), &[0, 1, 2], FS_HZ as u32);
    for (axis, slot) in img.axes.iter_mut().enumerate() {
        let a = slot.as_mut().expect("all axes present");
        // Per-axis variation: mode frequencies scaled, different FIR taps.
        let scale = 1.0 + 0.07 * axis as f64;
        let mut secs: Vec<Section> = blocks
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let (f, zeta) = if axis == 2 {
                    (2_000.0 * 11.0f64.powf(i as f64 / 23.0), 0.2 + 0.02 * (i % 5) as f64)
                } else {
                    let f = (100.0 * scale * 200.0f64.powf(i as f64 / 23.0)).min(22_000.0);
                    (f, 0.01 + 0.01 * ((i + axis) % 5) as f64)
                };
                to_section(&mode_block(f, zeta, FS_HZ, b.c))
            })
            .collect();
        if axis == 1 {
            secs[23] = Section::first_order(0.995, 1.0, 0.004);
        }
        if axis == 2 {
            // A diagonal section: two real poles (the M4's real-pole loop
            // runs twice, after an even pair count).
            secs[22] = Section { delta: [0.97 - 1.0, 0.0, 0.0, 0.6 - 1.0], b: [1.0, 1.0], c: [0.003, -0.02] };
        }
        // 24, 23 and 5 taps: the M4's assembly FIR loop (kernel_m4.rs)
        // runs blocks of four, then the rest one by one (0, 3 and 1 here).
        let taps = [24, 23, 5][axis];
        let fir: Vec<f32> =
            (0..taps).map(|j| 0.3 * (-0.4 * j as f32).exp() * if j % 2 == 0 { 1.0 } else { -0.7 }).collect();
        a.filter = AxisFilter::with_fir(&secs, d as f32 - 0.1 * axis as f32, &fir).expect("valid test filter");
    }
    img
}

/// Varied forces in N: tones, a step, an impulse, white noise with a
/// deterministic generator, full ±5 kN range, and silence at the end.
fn test_input() -> Vec<[f32; AXES]> {
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut noise = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..FRAMES)
        .map(|k| {
            let t = k as f64 / FS_HZ;
            let mut frame = [0.0f32; AXES];
            for (axis, v) in frame.iter_mut().enumerate() {
                let tone = 800.0 * (2.0 * std::f64::consts::PI * (1_100.0 + 300.0 * axis as f64) * t).sin()
                    + 150.0 * (2.0 * std::f64::consts::PI * 7_300.0 * t).sin();
                let step = if k > FRAMES / 4 { 2_000.0 } else { 0.0 };
                let impulse = if k == FRAMES / 2 + axis { 5_000.0 } else { 0.0 };
                let u = tone + step + impulse + 40.0 * noise();
                *v = if k >= FRAMES - 4_096 { 0.0 } else { u as f32 };
            }
            frame
        })
        .collect()
}

/// The host side: the same kernel on x86-64.
fn host_outputs(image: &CoeffImage, input: &[[f32; AXES]]) -> Vec<[f32; AXES]> {
    let mut states = [AxisState::default(); AXES];
    input
        .iter()
        .map(|frame| {
            let mut out = *frame;
            for axis in 0..AXES {
                if let Some(a) = &image.axes[axis] {
                    out[axis] = a.filter.step(&mut states[axis], frame[axis]);
                }
            }
            out
        })
        .collect()
}

/// The host side through the block path (`AxisFilter::process_block`, as
/// `dynocomp compensate` runs it), in blocks of uneven lengths with the
/// state carried across.
fn host_block_outputs(image: &CoeffImage, input: &[[f32; AXES]]) -> Vec<[f32; AXES]> {
    let mut out = input.to_vec();
    for axis in 0..AXES {
        let Some(a) = &image.axes[axis] else { continue };
        let u: Vec<f32> = input.iter().map(|f| f[axis]).collect();
        let mut y = vec![0.0f32; u.len()];
        let mut state = AxisState::default();
        let (mut start, mut len) = (0, 1);
        while start < u.len() {
            let end = (start + len).min(u.len());
            a.filter.process_block(&mut state, &u[start..end], &mut y[start..end]);
            start = end;
            len = len * 3 + 1; // 1, 4, 13, 40, ..., 9841, ...
        }
        for (f, v) in out.iter_mut().zip(y) {
            f[axis] = v;
        }
    }
    out
}

/// First sample whose bit pattern differs: `(index, axis, target, host)`.
fn first_mismatch(target: &[[f32; AXES]], host: &[[f32; AXES]]) -> Option<(usize, usize, f32, f32)> {
    target
        .iter()
        .zip(host)
        .enumerate()
        .find_map(|(k, (t, h))| (0..AXES).find(|&a| t[a].to_bits() != h[a].to_bits()).map(|a| (k, a, t[a], h[a])))
}

fn frames_to_bytes(frames: &[[f32; AXES]]) -> Vec<u8> {
    frames.iter().flatten().flat_map(|v| v.to_le_bytes()).collect()
}

fn bytes_to_frames(bytes: &[u8]) -> Vec<[f32; AXES]> {
    bytes
        .chunks_exact(4 * AXES)
        .map(|f| core::array::from_fn(|a| f32::from_le_bytes(f[4 * a..4 * a + 4].try_into().unwrap())))
        .collect()
}

fn require_qemu() {
    match Command::new("qemu-system-arm").arg("--version").stdout(Stdio::null()).status() {
        Ok(s) if s.success() => {}
        _ => panic!("qemu-system-arm is not installed (needed to run the kernel on the Cortex-M4F): {INSTALL_HINT}"),
    }
}

/// Build `qemu/`'s `kernel_io` for thumbv7em-none-eabihf; returns the ELF.
fn build_target_program() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let target_dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qemu-target");
    let mut build = common::firmware_cargo_build(&root.join("qemu"));
    build
        .args(["--bin", "kernel_io"])
        .env("CARGO_TARGET_DIR", &target_dir)
        // Replaces the repository's firmware link flags (defmt.x), see scripts/qemu_icount.sh.
        .env("RUSTFLAGS", "-C link-arg=-Tlink.x");
    let out = build.output().expect("run cargo to build qemu/");
    assert!(
        out.status.success(),
        "building qemu/ for thumbv7em-none-eabihf failed (is the target installed? `rustup target add thumbv7em-none-eabihf`):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    target_dir.join("thumbv7em-none-eabihf/release/kernel_io")
}

/// Run the ELF in `dir` under QEMU; returns (success, semihosting stdout+stderr).
fn run_qemu(elf: &Path, dir: &Path) -> (bool, String) {
    let mut child = Command::new("qemu-system-arm")
        .current_dir(dir)
        .args(["-M", "mps2-an386", "-cpu", "cortex-m4", "-nographic", "-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(elf)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start qemu-system-arm ({e}): {INSTALL_HINT}"));
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait for qemu") {
            break s;
        }
        if start.elapsed() > QEMU_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("qemu-system-arm did not finish within {QEMU_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = child.wait_with_output().expect("qemu output");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    (status.success(), text)
}

fn fresh_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create run directory");
    dir
}

#[test]
fn kernel_on_cortex_m4f_is_bit_identical_to_the_host() {
    require_qemu();
    let elf = build_target_program();
    let image = test_image();
    let input = test_input();
    let dir = fresh_dir("qemu-bit-exact");
    std::fs::write(dir.join("image.dcimg"), encode_image(&image)).unwrap();
    std::fs::write(dir.join("input.bin"), frames_to_bytes(&input)).unwrap();

    let (ok, log) = run_qemu(&elf, &dir);
    assert!(ok, "kernel_io failed on the emulated Cortex-M4F:\n{log}");
    let fpscr = log
        .lines()
        .find_map(|l| l.strip_prefix("FPSCR=0x"))
        .and_then(|h| u32::from_str_radix(h.trim(), 16).ok())
        .unwrap_or_else(|| panic!("kernel_io did not report FPSCR:\n{log}"));
    // FZ (bit 24), DN (bit 25) clear, RMode (bits 23:22) = round to nearest.
    assert_eq!(fpscr & (0b1111 << 22), 0, "FPSCR = {fpscr:#010x}: flush-to-zero/default-NaN/rounding mode set");

    let target = bytes_to_frames(&std::fs::read(dir.join("output.bin")).expect("kernel_io wrote output.bin"));
    assert_eq!(target.len(), input.len(), "output.bin has {} frames, input {}", target.len(), input.len());
    let host = host_outputs(&image, &input);
    // Target `step` == host `step`, and == host `process_block` (the
    // offline compensator's path).
    let host_block = host_block_outputs(&image, &input);
    for (path, host) in [("step", &host), ("process_block", &host_block)] {
        if let Some((k, axis, t, h)) = first_mismatch(&target, host) {
            panic!(
                "first differing sample (host {path}): axis {axis}, index {k}: Cortex-M4F {t:e} ({:#010x}), x86-64 {h:e} ({:#010x})",
                t.to_bits(),
                h.to_bits()
            );
        }
    }
    // The record must have exercised the filters (not pass-through), and
    // axis z's output must have passed through the subnormal range (the
    // comparison then covers the FPU's subnormal arithmetic).
    assert!(host.iter().zip(&input).any(|(y, u)| y[0] != u[0]));
    let subnormal_outputs = host.iter().filter(|y| y[2].is_subnormal()).count();
    assert!(subnormal_outputs > 10, "only {subnormal_outputs} subnormal outputs on axis z");
}

/// The host side of a 3x3 filter: `MimoFilter::step` on x86-64.
fn host_mimo_outputs(filter: &MimoFilter, input: &[[f32; AXES]]) -> Vec<[f32; AXES]> {
    let mut state = MimoState::default();
    input.iter().map(|u| filter.step(&mut state, *u)).collect()
}

/// The 3x3 filters of the bit-exactness test: `mimo_test_filter`'s pairs
/// and diagonal sections, the diagonals moved to every `spread`-th place
/// (the assembly's out-of-line diagonal path between pairs, `src/mimo_m4.rs`).
fn mimo_filter_interleaved(pairs: usize, diagonals: usize, taps: usize, spread: usize, seed: u64) -> MimoFilter {
    let f = mimo_test_filter(FS_HZ, pairs, diagonals, taps, seed);
    let (pair_secs, diag_secs) = f.sections().split_at(pairs);
    let mut secs = pair_secs.to_vec();
    for (i, d) in diag_secs.iter().enumerate() {
        secs.insert(((i + 1) * spread).min(secs.len()), *d);
    }
    MimoFilter::new(&secs, *f.d(), f.fir()).expect("a reordered valid filter is valid")
}

#[test]
fn the_3x3_kernel_on_cortex_m4f_is_bit_identical_to_the_host() {
    // Realistic 3x3 compensators (common::mimo_test_filter): normal-form
    // pairs (100 Hz … 22 kHz, 1-5 % damping), diagonal sections, every B,
    // C and tap entry non-zero; the same varied input as the per-axis test
    // (tones, step, impulses, noise, silence). The shapes cover each path of
    // the Cortex-M4F's assembly: diagonals after the pairs and between them,
    // even and odd tap counts, the most sections (48) and taps (24), and no
    // taps at all.
    require_qemu();
    let elf = build_target_program();
    let input = test_input();
    let filters = [
        ("20 pairs, 2 diagonals last, 8 taps", mimo_test_filter(FS_HZ, 20, 2, 8, 0xB17E)),
        ("13 pairs, 3 diagonals between, 5 taps", mimo_filter_interleaved(13, 3, 5, 4, 0x5EC7)),
        ("44 pairs, 4 diagonals between, 24 taps", mimo_filter_interleaved(44, 4, 24, 9, 0x48)),
        ("7 pairs, 1 diagonal first, no taps", mimo_filter_interleaved(7, 1, 0, 0, 0x70)),
    ];
    for (what, filter) in filters {
        let image = matrix_image(filter, FS_HZ as u32);
        let dir = fresh_dir("qemu-bit-exact-3x3");
        std::fs::write(dir.join("image.dcimg"), encode_matrix(&image)).unwrap();
        std::fs::write(dir.join("input.bin"), frames_to_bytes(&input)).unwrap();
        let (ok, log) = run_qemu(&elf, &dir);
        assert!(ok, "{what}: kernel_io failed on the emulated Cortex-M4F:\n{log}");
        let target = bytes_to_frames(&std::fs::read(dir.join("output.bin")).expect("kernel_io wrote output.bin"));
        assert_eq!(target.len(), input.len());
        let host = host_mimo_outputs(&image.filter, &input);
        if let Some((k, axis, t, h)) = first_mismatch(&target, &host) {
            panic!(
                "{what}: first differing sample: output {axis}, index {k}: Cortex-M4F {t:e} ({:#010x}), x86-64 {h:e} ({:#010x})",
                t.to_bits(),
                h.to_bits()
            );
        }
        // It compensated (not a copy of the input), and every output reads
        // every input: a force on x alone moves y and z.
        assert!(host.iter().zip(&input).any(|(y, u)| y[0] != u[0]), "{what}");
        let mut st = MimoState::default();
        let y: Vec<[f32; 3]> =
            (0..64).map(|k| image.filter.step(&mut st, [if k == 0 { 1.0 } else { 0.0 }, 0.0, 0.0])).collect();
        assert!(y.iter().any(|v| v[1] != 0.0) && y.iter().any(|v| v[2] != 0.0), "{what}");
    }
}

#[test]
fn target_program_refuses_a_corrupted_image() {
    require_qemu();
    let elf = build_target_program();
    let mut bytes = encode_image(&test_image());
    bytes[100] ^= 0x01; // breaks the CRC
    let dir = fresh_dir("qemu-bad-image");
    std::fs::write(dir.join("image.dcimg"), &bytes).unwrap();
    std::fs::write(dir.join("input.bin"), frames_to_bytes(&test_input()[..16])).unwrap();
    let (ok, log) = run_qemu(&elf, &dir);
    assert!(!ok, "kernel_io ran a corrupted image:\n{log}");
    assert!(log.contains("not a valid coefficient image"), "{log}");
    assert!(!dir.join("output.bin").exists(), "no output may be written for a corrupted image");
}

#[test]
fn the_comparison_reports_the_first_differing_sample() {
    let host = vec![[1.0f32, 2.0, 3.0]; 10];
    let mut target = host.clone();
    assert_eq!(first_mismatch(&target, &host), None);
    // One ulp on axis 2 at index 7, and a -0.0 vs 0.0 at index 9.
    target[7][2] = f32::from_bits(3.0f32.to_bits() + 1);
    target[9][1] = -0.0;
    let m = first_mismatch(&target, &host).unwrap();
    assert_eq!((m.0, m.1), (7, 2));
    let mut zeros = vec![[0.0f32; AXES]; 3];
    let host0 = zeros.clone();
    zeros[1][0] = -0.0;
    assert_eq!(first_mismatch(&zeros, &host0).map(|m| (m.0, m.1)), Some((1, 0)));
}
