//! 3x3 images (format 3) on the host side of the link: the virtual box
//! runs them to the bit as the documented equations (scaling around
//! `MimoFilter::step`), `inspect` summarises their shared filter and their
//! cost per sample against the box's budget, `flash --dry-run` plans them,
//! the box refuses one over its budget, and `compensate` says it cannot run
//! them instead of silently doing something else.

use crate::cli_common;
use crate::common;

use cli_common::dynocomp;
use dynocomp::link::sim_flash::SimFlash;
use dynocomp::link::virtual_box::VirtualBox;
use dynocomp::offline::compensate::look_ahead;
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

/// `compensate` runs a 3x3 image with the box's kernel: the output is the
/// kernel's, stepped here on the same f32 inputs, shifted back by the
/// declared latency (last input held for the last samples), written in
/// full; a record without all three forces, and `--offline`, are refused
/// by name, leaving no output.
#[test]
fn compensate_runs_a_3x3_image_like_the_kernel() {
    use dynocomp_core::mimo::MimoState;
    let image = common::matrix_image(8, 51_200, 2, 3);
    let img = tmp("c.dcimg");
    std::fs::write(&img, common::matrix_bytes(&image)).unwrap();
    let n = 200;
    let u: Vec<[f32; 3]> = (0..n)
        .map(|k| {
            let t = k as f32;
            [(0.3 * t).sin() * 50.0, (0.11 * t).cos() * 20.0 + 5.0, if k > 50 { 30.0 } else { -10.0 }]
        })
        .collect();
    let mut csv = String::from("fx,fy,fz\n");
    for v in &u {
        csv.push_str(&format!("{},{},{}\n", v[0], v[1], v[2]));
    }
    let input = tmp("in.csv");
    std::fs::write(&input, csv).unwrap();
    let out = tmp("out.csv");
    let (img_s, input_s, out_s) = (img.to_str().unwrap(), input.to_str().unwrap(), out.to_str().unwrap());
    let (ok, _, err) = dynocomp(&["compensate", "--coeffs", img_s, "--input", input_s, "--output", out_s]);
    assert!(ok, "{err}");
    let lag = usize::from(image.latency_samples);
    let mut st = MimoState::default();
    // The record, then each channel's look-ahead (its predicted continuation).
    let tails: Vec<Vec<f32>> = (0..3).map(|c| look_ahead(&u.iter().map(|v| v[c]).collect::<Vec<_>>(), lag)).collect();
    let fed = |k: usize| if k < n { u[k] } else { std::array::from_fn(|c| tails[c][k - n]) };
    let expected: Vec<[f32; 3]> = (0..n + lag).map(|k| image.filter.step(&mut st, fed(k))).skip(lag).collect();
    let text = std::fs::read_to_string(&out).unwrap();
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), n);
    for (k, (r, e)) in rows.iter().zip(&expected).enumerate() {
        for c in 0..3 {
            let tol = 1e-6 * f64::from(e[c].abs()).max(1.0);
            assert!((r[c] - f64::from(e[c])).abs() <= tol, "sample {k} axis {c}: {} against {}", r[c], e[c]);
        }
    }
    // Negative control: the unshifted kernel output differs from what was written.
    let mut st = MimoState::default();
    let unshifted: Vec<[f32; 3]> = u.iter().map(|v| image.filter.step(&mut st, *v)).collect();
    assert!(rows.iter().zip(&unshifted).any(|(r, e)| (r[0] - f64::from(e[0])).abs() > 1e-3));

    let only_xy = tmp("xy.csv");
    std::fs::write(&only_xy, "fx,fy\n1,2\n3,4\n").unwrap();
    let out2 = tmp("out2.csv");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img_s,
        "--input",
        only_xy.to_str().unwrap(),
        "--output",
        out2.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("fx, fy and fz") && err.contains("xy.csv"), "{err}");
    assert!(!out2.exists(), "partial output left behind");
    let (ok, _, err) = dynocomp(&[
        "compensate",
        "--coeffs",
        img_s,
        "--input",
        input_s,
        "--output",
        out2.to_str().unwrap(),
        "--offline",
    ]);
    assert!(!ok && err.contains("c.dcimg") && err.contains("--offline"), "{err}");
    assert!(!out2.exists(), "partial output left behind");
}

/// One `--frf` value holds one matrix as comma-separated files, one per
/// hammer direction: the per-axis design from the three files is the one
/// from the single file (same `inspect` apart from the id, time and source
/// hash); a missing file is named and nothing is written; an incomplete
/// matrix is designed per axis with a note naming the missing entries.
#[test]
fn one_frf_value_holds_a_matrix_as_files_per_hammer_direction() {
    let dir = tmp("split");
    std::fs::create_dir_all(&dir).unwrap();
    let p = |n: &str| dir.join(n).display().to_string();
    let (ok, _, err) =
        cli_common::simulate_plate(&p("sim"), "offcentre", "10240", &["--duration", "0.1", "--idle-duration", "0.2"]);
    assert!(ok, "{err}");
    let csv = std::fs::read_to_string(dir.join("sim/frf.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    for j in ["x", "y", "z"] {
        let keep: Vec<usize> = (0..header.len()).filter(|&c| c == 0 || header[c][1..2] == *j).collect();
        let mut out = keep.iter().map(|&c| header[c]).collect::<Vec<_>>().join(",") + "\n";
        for r in &rows {
            out += &(keep.iter().map(|&c| r[c]).collect::<Vec<_>>().join(",") + "\n");
        }
        std::fs::write(dir.join(format!("h{j}.csv")), out).unwrap();
    }
    let idle = p("sim/idle.csv");
    let design = |frf: &str, out: &str, extra: &[&str]| cli_common::design(frf, &idle, "10240", &p(out), extra);
    let inspect = |img: &str| {
        let (ok, out, err) = dynocomp(&["inspect", &p(img)]);
        assert!(ok, "{err}");
        out.lines()
            .filter(|l| !l.starts_with("image ") && !l.starts_with("source sha256"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let (ok, _, err) = design(&p("sim/frf.csv"), "one.dcimg", &["--per-axis"]);
    assert!(ok, "{err}");
    let list = format!("{},{},{}", p("hx.csv"), p("hy.csv"), p("hz.csv"));
    let (ok, _, err) = design(&list, "three.dcimg", &["--per-axis"]);
    assert!(ok, "{err}");
    assert_eq!(inspect("one.dcimg"), inspect("three.dcimg"));

    let missing = format!("{},{},{}", p("hx.csv"), p("nothere.csv"), p("hz.csv"));
    let (ok, _, err) = design(&missing, "m.dcimg", &["--per-axis"]);
    assert!(!ok && err.contains("nothere.csv"), "{err}");
    assert!(!dir.join("m.dcimg").exists());

    let two = format!("{},{}", p("hx.csv"), p("hy.csv"));
    let (ok, _, err) = design(&two, "two.dcimg", &[]);
    assert!(ok, "{err}");
    assert!(err.contains("missing") && err.contains("xz") && err.contains("zz"), "{err}");
}
