//! Host benchmarks (issue #6): `design` time, offline `compensate`
//! throughput for 1 and 3 axes, and kernel samples per second.
//!
//! `cargo bench -p dynocomp --bench throughput`; figures in BENCHMARKS.md.
//! Inputs: the bundled example (data/example: 4097-line UFF58 FRF, idle
//! record, 0.5 s of measured forces at 51.2 kHz).
use clap::Parser;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use dynocomp::cli::design::run;
use dynocomp::cli::design_args::DesignArgs;
use dynocomp::io::image_file::read_image;
use dynocomp::io::signal_csv::{read_signal_csv, SignalRecord};
use dynocomp::offline::compensate::compensate_record;
use dynocomp_core::kernel::{process_blocks, AxisFilter, AxisState, BlockJob, Section, MAX_FIR, MAX_SECTIONS};
use std::hint::black_box;
use std::path::{Path, PathBuf};

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    design: DesignArgs,
}

fn example(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/example").join(file)
}

/// `dynocomp design` on the bundled example, as the CLI runs it (no report).
fn design_args(out: &Path) -> DesignArgs {
    let frf = example("frf.uff");
    let idle = example("idle.csv");
    let argv = ["design", "--frf", frf.to_str().unwrap(), "--fs", "51200", "--idle", idle.to_str().unwrap()];
    let mut argv: Vec<String> = argv.iter().map(|s| s.to_string()).collect();
    argv.extend(["--out".to_string(), out.display().to_string()]);
    Cli::parse_from(argv).design
}

fn bench_design(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let args = design_args(&dir.path().join("b.dcimg"));
    let mut g = c.benchmark_group("design");
    g.sample_size(10);
    g.bench_function("example 3 axes", |b| b.iter(|| run(black_box(&args)).unwrap()));
    g.finish();
}

fn bench_compensate(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let img_path = dir.path().join("b.dcimg");
    run(&design_args(&img_path)).unwrap();
    let image = read_image(&img_path).unwrap();
    let rec = read_signal_csv(&example("measured.csv")).unwrap();
    let one = SignalRecord { t_s: None, channels: rec.channels[..1].to_vec() };
    let mut g = c.benchmark_group("compensate");
    for (name, r) in [("1 axis", &one), ("3 axes", &rec)] {
        g.throughput(Throughput::Elements((r.len() * r.channels.len()) as u64));
        g.bench_with_input(BenchmarkId::new("example image", name), r, |b, r| {
            b.iter(|| compensate_record(&image, black_box(r), false, "bench").unwrap())
        });
    }
    g.finish();

    // The kernel alone on the example's axis x filter and on a full axis.
    let example_x = image.axes[0].unwrap().filter;
    let full = full_filter();
    let input: Vec<f32> = rec.channels[0].1.iter().map(|&v| v as f32).collect();
    let mut out = vec![0.0f32; input.len()];
    let mut g = c.benchmark_group("kernel");
    g.throughput(Throughput::Elements(input.len() as u64));
    let label_x = format!("example x (S{}+F{})", example_x.sections().len(), example_x.fir().len());
    for (name, f) in [(label_x.as_str(), &example_x), ("S24+F24", &full)] {
        g.bench_function(format!("block {name}"), |b| {
            b.iter(|| {
                let mut st = AxisState::default();
                f.process_block(&mut st, black_box(&input), &mut out);
                black_box(&out);
            })
        });
        // The box's path: `step` per sample (bit-identical outputs).
        g.bench_function(format!("step {name}"), |b| {
            b.iter(|| {
                let mut st = AxisState::default();
                for (u, y) in black_box(&input).iter().zip(out.iter_mut()) {
                    *y = f.step(&mut st, *u);
                }
                black_box(&out);
            })
        });
    }
    // The example's three axes: one after the other, and in lockstep
    // (`process_blocks`, the same numbers), in the same run.
    let filters: Vec<AxisFilter> = image.axes.iter().map(|a| a.unwrap().filter).collect();
    let inputs: Vec<Vec<f32>> = rec.channels.iter().map(|(_, c)| c.iter().map(|&v| v as f32).collect()).collect();
    let mut outputs: Vec<Vec<f32>> = inputs.iter().map(|u| vec![0.0f32; u.len()]).collect();
    g.throughput(Throughput::Elements(3 * input.len() as u64));
    g.bench_function("block x, y, z in turn", |b| {
        b.iter(|| {
            for ((f, u), y) in filters.iter().zip(&inputs).zip(outputs.iter_mut()) {
                f.process_block(&mut AxisState::default(), black_box(u), y);
            }
            black_box(&outputs);
        })
    });
    g.bench_function("lockstep x+y+z", |b| {
        b.iter(|| {
            let mut states = [AxisState::default(); 3];
            let mut jobs: Vec<BlockJob<'_>> = filters
                .iter()
                .zip(states.iter_mut())
                .zip(inputs.iter().zip(outputs.iter_mut()))
                .map(|((filter, state), (input, output))| BlockJob { filter, state, input: black_box(input), output })
                .collect();
            process_blocks(&mut jobs);
            black_box(&outputs);
        })
    });
    g.finish();
}

/// The largest filter an image can hold: 24 stable sections + 24 taps.
fn full_filter() -> AxisFilter {
    let secs: Vec<Section> = (0..MAX_SECTIONS)
        .map(|i| {
            let w = 0.001 + 0.0015 * i as f32;
            Section { delta: [-0.002, w, -w, -0.002], b: [0.1, 0.0], c: [0.5, -0.2] }
        })
        .collect();
    let fir: Vec<f32> = (0..MAX_FIR).map(|j| 0.1 / (j as f32 + 1.0)).collect();
    AxisFilter::with_fir(&secs, 0.25, &fir).unwrap()
}

criterion_group!(benches, bench_design, bench_compensate);
criterion_main!(benches);
