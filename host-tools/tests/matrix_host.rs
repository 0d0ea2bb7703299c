//! 3x3 images (format 3) on the host side of the link: the virtual box
//! runs them to the bit as the documented equations (scaling around
//! `MimoFilter::step`), `inspect` summarises their shared filter and their
//! cost per sample against the box's budget, `flash --dry-run` plans them,
//! the box refuses one over its budget, and `compensate` says it cannot run
//! them instead of silently doing something else.

mod cli_common;
mod common;

use cli_common::dynocomp;
use dynocomp::link::sim_flash::SimFlash;
use dynocomp::link::virtual_box::VirtualBox;
use dynocomp_core::budget::{image_load, BOX_LOAD_LIMIT_PERMILLE};
use dynocomp_core::image::{BoxImage, MatrixImage, CRC32};
use dynocomp_core::mimo::MimoState;
use dynocomp_core::protocol::*;
use dynocomp_core::sample::BypassReason;

fn tmp(name: &str) -> std::path::PathBuf {
    cli_common::tmp("matrix-host", name)
}

fn frame(id: u16, request: Request<'_>) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_frame(&RequestFrame { id, request }, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn messages(bytes: &[u8]) -> Vec<BoxMessage> {
    let mut dec = FrameDecoder::new();
    let mut out = vec![];
    dec.push(bytes, |r| out.push(decode_message::<BoxMessage>(r.expect("valid frame")).expect("decodes")));
    out
}

/// Upload `img` through the box's request handler; the replies.
fn upload(vbox: &mut VirtualBox, img: &[u8]) -> Vec<Reply> {
    let mut reqs = vec![frame(1, Request::UploadBegin { len: img.len() as u32, crc: CRC32.checksum(img) })];
    for (i, c) in img.chunks(MAX_CHUNK).enumerate() {
        reqs.push(frame(2, Request::UploadChunk { offset: (i * MAX_CHUNK) as u32, bytes: c }));
    }
    reqs.push(frame(3, Request::UploadCommit));
    messages(&vbox.receive(&reqs.concat()))
        .into_iter()
        .filter_map(|m| match m {
            BoxMessage::Reply { reply, .. } => Some(reply),
            _ => None,
        })
        .collect()
}

/// The DAC codes the documented equations give for `raw`, with `img`'s
/// scaling and filter run from `state` (docs/image-format.md §13.6).
fn expected_dac(img: &MatrixImage, state: &mut MimoState, raw: [u16; 3]) -> [u16; 3] {
    let u: [f32; 3] = std::array::from_fn(|i| {
        let s = &img.axes[i].scaling;
        (f32::from(raw[i]) - s.adc_offset_code) * s.newton_per_code
    });
    let y = img.filter.step(state, u);
    std::array::from_fn(|i| {
        let s = &img.axes[i].scaling;
        (s.dac_offset_code + y[i] * s.dac_code_per_newton).round().clamp(0.0, 4095.0) as u16
    })
}

/// Stream `n` samples of the virtual box (decimation 1) and compare each
/// with the equations run on a copy of `img`; the number of mismatches.
fn mismatches(vbox: &mut VirtualBox, img: &MatrixImage, n: usize) -> (usize, usize) {
    let r = messages(&vbox.receive(&frame(4, Request::StartStream { decimation: 1 })));
    assert!(r.iter().any(|m| matches!(m, BoxMessage::Reply { reply: Reply::Ack, .. })), "{r:?}");
    let mut state = MimoState::default();
    let (mut seen, mut bad) = (0, 0);
    for m in messages(&vbox.run_samples(n)) {
        if let BoxMessage::Stream(f) = m {
            for s in f.valid() {
                let want = expected_dac(img, &mut state, s.raw);
                seen += 1;
                bad += usize::from(s.out != want);
            }
        }
    }
    (seen, bad)
}

#[test]
fn the_virtual_box_runs_a_3x3_image_to_the_bit() {
    let img = common::matrix_image(1, 51_200, 6, 4);
    let bytes = common::matrix_bytes(&img);
    let mut vbox = VirtualBox::boot(SimFlash::g474_slots(), []).unwrap();
    assert_eq!(upload(&mut vbox, &bytes).last(), Some(&Reply::Ack));
    assert_eq!(vbox.running(), Some(&BoxImage::Matrix(img)));
    let (seen, bad) = mismatches(&mut vbox, &img, 3_000);
    assert!(seen >= 2_900, "{seen} samples streamed");
    assert_eq!(bad, 0, "{bad} of {seen} samples differ from the equations");

    // Negative control: the same comparison against a filter with one
    // cross term changed (output x from input y, first pair) finds
    // mismatches, so it does see the crosstalk terms.
    let mut other = img;
    let mut secs = img.filter.sections().to_vec();
    secs[0].b[0][1] *= 1.5;
    other.filter = dynocomp_core::mimo::MimoFilter::new(&secs, *img.filter.d(), img.filter.fir()).unwrap();
    let mut vbox = VirtualBox::boot(SimFlash::g474_slots(), []).unwrap();
    assert_eq!(upload(&mut vbox, &bytes).last(), Some(&Reply::Ack));
    let (_, bad) = mismatches(&mut vbox, &other, 3_000);
    assert!(bad > 0, "a changed cross term went unnoticed");
}

#[test]
fn the_box_refuses_a_3x3_image_over_its_budget_and_keeps_the_old_one() {
    let good = common::matrix_image(2, 51_200, 6, 4);
    let heavy = common::matrix_image(3, 51_200, 40, 24);
    assert!(image_load(&good).permille <= BOX_LOAD_LIMIT_PERMILLE);
    assert!(image_load(&heavy).permille > BOX_LOAD_LIMIT_PERMILLE, "{:?}", image_load(&heavy));
    let mut vbox = VirtualBox::boot(SimFlash::g474_slots(), []).unwrap();
    assert_eq!(upload(&mut vbox, &common::matrix_bytes(&good)).last(), Some(&Reply::Ack));
    let r = upload(&mut vbox, &common::matrix_bytes(&heavy));
    let over = |l: &dynocomp_core::budget::Load| *l == image_load(&heavy);
    let hit = matches!(r.last(), Some(Reply::Error(LinkError::NotRunnable(BypassReason::OverBudget(l)))) if over(l));
    assert!(hit, "{r:?}");
    assert_eq!(vbox.running(), Some(&BoxImage::Matrix(good)));
}

#[test]
fn inspect_summarises_a_3x3_image_and_its_cost() {
    let img = common::matrix_image(4, 51_200, 5, 3);
    let path = tmp("m.dcimg");
    std::fs::write(&path, common::matrix_bytes(&img)).unwrap();
    let p = path.to_str().unwrap();
    let (ok, out, err) = dynocomp(&["inspect", p]);
    assert!(ok, "{err}");
    assert!(out.contains("format v3"), "{out}");
    let shape = "3x3 filter (shared by x, y, z): 5 sections (5 pole pairs, 0 diagonal), order 10, 3 FIR taps";
    assert!(out.contains(shape), "{out}");
    assert!(out.contains("output rows: x 3x3, y per-axis, z 3x3"), "{out}");
    assert!(out.contains("box CPU load at 51200 Hz:"), "{out}");
    assert!(!out.contains("cannot run"), "{out}");
    let (ok, out, err) = dynocomp(&["inspect", p, "--json"]);
    assert!(ok, "{err}");
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["format_version"], 3);
    assert_eq!(j["runs_in_box"], true);
    assert_eq!(j["matrix"]["sections"], 5);
    assert_eq!(j["matrix"]["fir_taps"], 3);
    assert_eq!(j["axes"][1]["row_design"], "per-axis");
    // The cost is the core's 3x3 cost model at this shape.
    let load = image_load(&img);
    assert_eq!(j["box_load"]["cycles"][1], load.cycles);
    assert_eq!(j["box_load"]["fits"], true);
    // The fixture's DC gain is the identity (by construction).
    for i in 0..3 {
        for k in 0..3 {
            let g = j["matrix"]["dc_gain"][i][k].as_f64().unwrap();
            assert!((g - f64::from(u8::from(i == k))).abs() < 1e-5, "dc_gain[{i}][{k}] = {g}");
        }
    }

    // Negative control: over the budget, inspect says the box cannot run it.
    let heavy = tmp("heavy.dcimg");
    std::fs::write(&heavy, common::matrix_bytes(&common::matrix_image(5, 51_200, 40, 24))).unwrap();
    let (ok, out, err) = dynocomp(&["inspect", heavy.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.contains("cannot run this image inline") && out.contains("OverBudget"), "{out}");
}

#[test]
fn flash_dry_run_takes_a_3x3_image_and_refuses_one_over_budget() {
    let good = tmp("good.dcimg");
    std::fs::write(&good, common::matrix_bytes(&common::matrix_image(6, 51_200, 6, 4))).unwrap();
    let (ok, out, err) = dynocomp(&["flash", good.to_str().unwrap(), "--probe", "--dry-run"]);
    assert!(ok, "{out}{err}");
    let heavy = tmp("heavy-flash.dcimg");
    std::fs::write(&heavy, common::matrix_bytes(&common::matrix_image(7, 51_200, 40, 24))).unwrap();
    let (ok, _, err) = dynocomp(&["flash", heavy.to_str().unwrap(), "--probe", "--dry-run"]);
    assert!(!ok, "an over-budget 3x3 image was planned");
    assert!(err.contains("heavy-flash.dcimg") && err.contains("limit"), "{err}");
}

#[test]
fn compensate_says_it_cannot_run_a_3x3_image() {
    let img = tmp("c.dcimg");
    std::fs::write(&img, common::matrix_bytes(&common::matrix_image(8, 51_200, 2, 0))).unwrap();
    let input = tmp("in.csv");
    std::fs::write(&input, "t_s,fx,fy,fz\n0,1,2,3\n1.953125e-5,1,2,3\n").unwrap();
    let out = tmp("out.csv");
    let (img, input, out_s) = (img.to_str().unwrap(), input.to_str().unwrap(), out.to_str().unwrap());
    let (ok, _, err) = dynocomp(&["compensate", "--coeffs", img, "--input", input, "--output", out_s]);
    assert!(!ok);
    assert!(err.contains("c.dcimg") && err.contains("3x3 image"), "{err}");
    assert!(!out.exists(), "partial output left behind");
}
