//! `AxisFilter::process_block` (loop-interchanged, for throughput) against
//! the per-sample `step`, which runs on the box: outputs and final state
//! must be identical to the bit (`f32::to_bits`), for random stable filters
//! (0-24 sections of every kind, 0-24 taps), block lengths 0, 1, odd, and
//! longer than a chunk, with the state carried from block to block. The
//! guarded variant must match `step_guarded` with the sample path's fallback
//! (raw input) sample for sample, including the reset count.
use dynocomp_core::kernel::{
    process_blocks, AxisFilter, AxisState, BlockJob, Section, BLOCK_CHUNK, MAX_FIR, MAX_SECTIONS,
};
use proptest::prelude::*;

/// A stable section of each shape the kernel runs: a conjugate pair
/// r·e^{±jθ} (normal form, b = [β, 0]), a first-order section (second state
/// unused), or two real poles in a diagonal block; b, c of mixed sign and
/// magnitude, zeros included (a state with b·c = 0 is dropped).
fn arb_section() -> impl Strategy<Value = Section> {
    let gain = prop_oneof![-2.0f32..2.0, -500.0f32..500.0, Just(0.0f32)];
    (
        0u8..3,
        0.0f32..0.9999,
        0.0f32..std::f32::consts::PI,
        -0.99f32..0.99,
        -1.0f32..1.0,
        gain.clone(),
        gain.clone(),
        gain.clone(),
        gain,
    )
        .prop_map(|(kind, r, th, p2, t, b1, b2, c1, c2)| match kind {
            0 => {
                let (re, im) = (r * th.cos(), r * th.sin());
                Section { delta: [re - 1.0, im, -im, re - 1.0], b: [b1, 0.0], c: [c1, c2] }
            }
            1 => Section::first_order(r * th.cos(), b1, c1),
            _ => Section { delta: [r * t.abs() - 1.0, 0.0, 0.0, p2 - 1.0], b: [b1, b2], c: [c1, c2] },
        })
        .prop_filter("stable", Section::is_stable)
}

fn arb_filter() -> impl Strategy<Value = AxisFilter> {
    (
        proptest::collection::vec(arb_section(), 0..=MAX_SECTIONS),
        proptest::collection::vec(-50.0f32..50.0, 0..=MAX_FIR),
        prop_oneof![-3.0f32..3.0, Just(0.0f32), Just(-0.0f32)],
    )
        .prop_map(|(s, h, d)| AxisFilter::with_fir(&s, d, &h).unwrap())
}

/// Forces with exact zeros (both signs), tiny values (subnormal products)
/// and large values mixed in.
fn input(seed: u64, n: usize) -> Vec<f32> {
    let mut s = seed | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let v = ((s >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2000.0;
            match s % 16 {
                0 => 0.0,
                1 => -0.0,
                2 => v * 1e-38,
                3 => v * 1e3,
                _ => v,
            }
        })
        .collect()
}

fn state_bits(st: &AxisState) -> (Vec<u32>, Vec<u32>, u32) {
    (
        st.x.iter().flatten().chain(&st.x_real).map(|v| v.to_bits()).collect(),
        st.fir_hist.iter().map(|v| v.to_bits()).collect(),
        st.nonfinite_resets,
    )
}

/// Blocks of the given lengths through `block`, each compared bit for bit
/// with `reference` per sample; the states must agree after every block.
fn check_blocks(
    f: &AxisFilter,
    seed: u64,
    lens: &[usize],
    block: impl Fn(&AxisFilter, &mut AxisState, &[f32], &mut [f32]),
    reference: impl Fn(&AxisFilter, &mut AxisState, f32) -> f32,
) -> Result<(), TestCaseError> {
    let total: usize = lens.iter().sum();
    let u = input(seed, total);
    let (mut st_ref, mut st_blk) = (AxisState::default(), AxisState::default());
    let mut start = 0;
    for (b, &len) in lens.iter().enumerate() {
        let chunk = &u[start..start + len];
        let mut out = vec![f32::NAN; len];
        block(f, &mut st_blk, chunk, &mut out);
        for (k, (&x, &y)) in chunk.iter().zip(&out).enumerate() {
            let want = reference(f, &mut st_ref, x);
            prop_assert_eq!(
                y.to_bits(),
                want.to_bits(),
                "block {} (length {}), sample {}: block {:e}, per-sample {:e}",
                b,
                len,
                k,
                y,
                want
            );
        }
        prop_assert_eq!(state_bits(&st_blk), state_bits(&st_ref), "state after block {}", b);
        start += len;
    }
    Ok(())
}

fn arb_lens() -> impl Strategy<Value = Vec<usize>> {
    let len = prop_oneof![
        Just(0usize),
        Just(1),
        Just(2),
        1usize..40,
        Just(BLOCK_CHUNK - 1),
        Just(BLOCK_CHUNK + 1),
        40usize..1500
    ];
    proptest::collection::vec(len, 1..7)
}

/// Several axes through `process_blocks`, call after call (the blocks of a
/// call may differ in length), each axis compared bit for bit with its own
/// per-sample `step`; every state must agree after every call.
/// `lens[call][axis]` is the block length of that axis in that call.
fn check_many(fs: &[AxisFilter], seed: u64, lens: &[Vec<usize>]) -> Result<(), TestCaseError> {
    let axes = fs.len();
    let u: Vec<Vec<f32>> =
        (0..axes).map(|a| input(seed.wrapping_add(a as u64), lens.iter().map(|l| l[a]).sum())).collect();
    let mut st_ref = vec![AxisState::default(); axes];
    let mut st_blk = vec![AxisState::default(); axes];
    let mut start = vec![0usize; axes];
    for (call, l) in lens.iter().enumerate() {
        let inputs: Vec<&[f32]> = (0..axes).map(|a| &u[a][start[a]..start[a] + l[a]]).collect();
        let mut outputs: Vec<Vec<f32>> = l.iter().map(|&n| vec![f32::NAN; n]).collect();
        let mut jobs: Vec<BlockJob<'_>> = fs
            .iter()
            .zip(st_blk.iter_mut())
            .zip(inputs.iter().zip(outputs.iter_mut()))
            .map(|((filter, state), (input, output))| BlockJob { filter, state, input, output })
            .collect();
        process_blocks(&mut jobs);
        for a in 0..axes {
            for (k, (&x, &y)) in inputs[a].iter().zip(&outputs[a]).enumerate() {
                let want = fs[a].step(&mut st_ref[a], x);
                prop_assert_eq!(
                    y.to_bits(),
                    want.to_bits(),
                    "call {} (lengths {:?}), axis {} of {}, sample {}: blocks {:e}, per-sample {:e}",
                    call,
                    l,
                    a,
                    axes,
                    k,
                    y,
                    want
                );
            }
            prop_assert_eq!(state_bits(&st_blk[a]), state_bits(&st_ref[a]), "axis {} state after call {}", a, call);
            start[a] += l[a];
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn lockstep_blocks_are_bit_identical_to_step(
        fs in proptest::collection::vec(arb_filter(), 1..=6),
        seed in any::<u64>(),
        lens in arb_lens(),
        skew in proptest::collection::vec(0usize..3, 1..7),
    ) {
        // Most calls give every axis the same length (as `compensate` does);
        // where `skew` says so, axis a's block is a samples shorter.
        let lens: Vec<Vec<usize>> = lens
            .iter()
            .zip(skew.iter().cycle())
            .map(|(&n, &s)| (0..fs.len()).map(|a| if s == 2 { n.saturating_sub(a) } else { n }).collect())
            .collect();
        check_many(&fs, seed, &lens)?;
    }

    #[test]
    fn block_is_bit_identical_to_step(f in arb_filter(), seed in any::<u64>(), lens in arb_lens()) {
        check_blocks(&f, seed, &lens, |f, st, u, y| f.process_block(st, u, y), |f, st, u| f.step(st, u))?;
    }

    #[test]
    fn guarded_block_matches_step_guarded(f in arb_filter(), seed in any::<u64>(), lens in arb_lens()) {
        check_blocks(
            &f,
            seed,
            &lens,
            |f, st, u, y| { f.process_block_guarded(st, u, y); },
            |f, st, u| f.step_guarded(st, u).unwrap_or(u),
        )?;
    }
}

/// The guard's fallback path: a filter whose output crosses the runaway
/// limit on large inputs and a NaN input. Both paths must reset at the same
/// samples, output the raw input there, and count the same resets.
#[test]
fn guarded_block_resets_like_step_guarded() {
    let s = [
        Section::first_order(0.99, 1.0e3, 1.0e2),
        Section { delta: [-0.01, 0.05, -0.05, -0.01], b: [10.0, 0.0], c: [3.0, 1.0] },
    ];
    let f = AxisFilter::with_fir(&s, 2.0, &[5.0, -4.0, 3.0]).unwrap();
    let mut u = input(7, 3000);
    u[100] = 1.0e6; // drives |y| past RUNAWAY_LIMIT_N
    u[1700] = f32::NAN;
    u[2999] = f32::INFINITY;
    let (mut st_ref, mut st_blk) = (AxisState::default(), AxisState::default());
    let mut resets_blk = 0;
    for chunk in u.chunks(700) {
        let mut out = vec![0.0; chunk.len()];
        resets_blk += f.process_block_guarded(&mut st_blk, chunk, &mut out);
        for (&x, &y) in chunk.iter().zip(&out) {
            let want = f.step_guarded(&mut st_ref, x).unwrap_or(x);
            assert_eq!(y.to_bits(), want.to_bits());
        }
        assert_eq!(state_bits(&st_blk), state_bits(&st_ref));
    }
    assert!(st_ref.nonfinite_resets >= 3, "the test input must trip the guard ({} resets)", st_ref.nonfinite_resets);
    assert_eq!(resets_blk, st_ref.nonfinite_resets);
}
