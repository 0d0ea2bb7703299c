//! The cost model of the sample interrupt (`dynocomp_core::budget`) against
//! the instructions `SamplePath::tick` (`process_sample` and the decisions around it) executes
//! on the emulated Cortex-M4F
//! (issue #16).
//!
//! Runs `scripts/qemu_icount.sh` (builds `qemu/`'s `icount` program, runs
//! it under `qemu-system-arm -icount shift=0`, where the count is exact; see
//! BENCHMARKS.md, "Instructions per sample on the Cortex-M4F"), reads its
//! `model P R T A <per call> <net>` lines (A axes, each with P pole pairs,
//! R real poles, T FIR taps) and requires the instruction model
//! [`CostModel::QEMU_INSNS`] to predict every count within its stated
//! uncertainty (`budget::insns_agree`). The cycle model
//! [`CostModel::CORTEX_M4`] is that model part by part times the TRM's
//! cycles per instruction, so a drift here is a drift there.
//!
//! Negative control: the same check with one coefficient of the model
//! off by 10 % (pairs), 20 % (taps, real poles, axis call, fixed part) or
//! 50 % (remainder taps) must reject at least one
//! measured shape. If `qemu-system-arm` is missing the test FAILS (like
//! `tests/qemu_bit_exact.rs`); `bash scripts/test.sh` installs it.

use dynocomp_core::budget::{insns_agree, AxisShape, Cost, CostModel, MimoCostModel, MimoShape, SHELL_INSNS};
use std::path::Path;
use std::process::Command;

struct Measured {
    shape: AxisShape,
    axes: usize,
    insns: u32,
}

/// The `shell … streaming S` figures: instructions of the interrupt's
/// software shell around `SamplePath::tick`, streaming every sample.
fn shell_counts(text: &str) -> Vec<u32> {
    text.lines()
        .filter(|l| l.starts_with("shell "))
        .map(|l| {
            l.rsplit("streaming ")
                .next()
                .and_then(|v| v.trim().parse::<f64>().ok())
                .expect("a shell line ends with 'streaming N'")
                .round() as u32
        })
        .collect()
}

/// The `mimo P D T <per call> <net>` lines: `SamplePath::tick` with a 3x3
/// image of P pairs, D diagonal sections and T taps.
fn mimo_counts(text: &str) -> Vec<(MimoShape, u32)> {
    text.lines()
        .filter_map(|l| l.strip_prefix("mimo "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().expect("number in a mimo line")).collect();
            (MimoShape { pairs: v[0] as u32, diagonals: v[1] as u32, taps: v[2] as u32 }, v[3].round() as u32)
        })
        .collect()
}

fn measure() -> (Vec<Measured>, Vec<u32>, Vec<(MimoShape, u32)>) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    if Command::new("qemu-system-arm").arg("--version").output().is_err() {
        panic!("qemu-system-arm not found: install it with `apt-get install -y --no-install-recommends qemu-system-arm`, or run `bash scripts/test.sh`");
    }
    let out =
        Command::new("bash").arg(root.join("scripts/qemu_icount.sh")).output().expect("run scripts/qemu_icount.sh");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "qemu_icount.sh failed: {}\n{}", text, String::from_utf8_lossy(&out.stderr));
    let rows: Vec<Measured> = text
        .lines()
        .filter_map(|l| l.strip_prefix("model "))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().expect("number in a model line")).collect();
            Measured {
                shape: AxisShape { pairs: v[0] as u32, reals: v[1] as u32, taps: v[2] as u32 },
                axes: v[3] as usize,
                insns: v[4].round() as u32,
            }
        })
        .collect();
    assert!(rows.len() >= 15, "expected the calibration grid's model lines, got {}:\n{text}", rows.len());
    let shell = shell_counts(&text);
    assert!(!shell.is_empty(), "expected the shell lines:\n{text}");
    let mimo = mimo_counts(&text);
    assert!(mimo.len() >= 12, "expected the 3x3 calibration grid's mimo lines, got {}:\n{text}", mimo.len());
    (rows, shell, mimo)
}

/// The 3x3 shapes the model misses beyond its uncertainty.
fn mimo_misses(model: &MimoCostModel, rows: &[(MimoShape, u32)]) -> Vec<String> {
    rows.iter()
        .filter_map(|&(shape, insns)| {
            let predicted = model.sample_cost(shape).high;
            (!insns_agree(predicted, insns)).then(|| format!("{shape:?}: model {predicted}, QEMU {insns}"))
        })
        .collect()
}

/// The shapes the model misses beyond its uncertainty (empty = agrees).
fn misses(model: &CostModel, rows: &[Measured]) -> Vec<String> {
    rows.iter()
        .filter_map(|m| {
            let predicted = model.sample_cost(&vec![m.shape; m.axes]).high;
            (!insns_agree(predicted, m.insns))
                .then(|| format!("{:?} x{}: model {predicted}, QEMU {}", m.shape, m.axes, m.insns))
        })
        .collect()
}

fn scaled(c: Cost, pct: u32) -> Cost {
    Cost { low: c.low * pct / 100, high: c.high * pct / 100 }
}

#[test]
fn cost_model_matches_the_qemu_instruction_counts() {
    let (rows, shell, mimo) = measure();
    let bad = misses(&CostModel::QEMU_INSNS, &rows);
    assert!(bad.is_empty(), "cost model drifted from the measured counts:\n{}", bad.join("\n"));
    // The interrupt shell's software (budget::SHELL_INSNS, in CORTEX_M4's
    // fixed part) is what the replica measures, for every image shape.
    for &s in &shell {
        assert!(insns_agree(SHELL_INSNS, s), "budget::SHELL_INSNS = {SHELL_INSNS}, QEMU measures {s}");
        // Negative control: a fifth less is caught.
        assert!(!insns_agree(SHELL_INSNS * 4 / 5, s));
    }

    // Negative controls: a model off in one part must be caught.
    let base = CostModel::QEMU_INSNS;
    for (what, m) in [
        ("pairs -10 %", CostModel { pair: scaled(base.pair, 90), ..base }),
        ("taps +20 %", CostModel { tap: scaled(base.tap, 120), ..base }),
        ("real poles -20 %", CostModel { real: scaled(base.real, 80), ..base }),
        ("axis call -20 %", CostModel { axis: scaled(base.axis, 80), ..base }),
        ("remainder taps -50 %", CostModel { tap_rem: scaled(base.tap_rem, 50), ..base }),
        ("fixed part -20 %", CostModel { fixed: scaled(base.fixed, 80), ..base }),
    ] {
        assert!(!misses(&m, &rows).is_empty(), "negative control '{what}' was not caught");
    }

    // The 3x3 path: the same check, with its own negative controls.
    let bad = mimo_misses(&MimoCostModel::QEMU_INSNS, &mimo);
    assert!(bad.is_empty(), "3x3 cost model drifted from the measured counts:\n{}", bad.join("\n"));
    let base = MimoCostModel::QEMU_INSNS;
    for (what, m) in [
        ("3x3 pairs -10 %", MimoCostModel { pair: scaled(base.pair, 90), ..base }),
        ("3x3 diagonals -10 %", MimoCostModel { diagonal: scaled(base.diagonal, 90), ..base }),
        ("3x3 taps +10 %", MimoCostModel { tap: scaled(base.tap, 110), ..base }),
        ("3x3 matrix part -20 %", MimoCostModel { matrix: scaled(base.matrix, 80), ..base }),
    ] {
        assert!(!mimo_misses(&m, &mimo).is_empty(), "negative control '{what}' was not caught");
    }
}
