//! Bit-exactness runner: the core kernel on the emulated Cortex-M4F.
//!
//! Reads `image.dcimg` (a coefficient image) and `input.bin` (frames of
//! 3 little-endian f32 forces in N, axes x, y, z) from QEMU's working
//! directory, runs every sample of each axis the image covers through
//! `AxisFilter::step` of `dynocomp-core` (the same crate the box and
//! `dynocomp compensate` use; axes the image does not cover are copied),
//! or, for a 3x3 image (format version 3), every frame through
//! `MimoFilter::step`,
//! and writes `output.bin` in the same layout. Prints `FPSCR=0x........`
//! (the float environment the outputs were computed in) and exits 0, or
//! prints the reason and exits 1. Driven by `tests/qemu_bit_exact.rs`.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use dynocomp_core::image::{BoxImage, MAX_BOX_IMAGE_LEN};
use dynocomp_core::kernel::AxisState;
use dynocomp_core::mimo::MimoState;
use dynocomp_core::AXES;
use dynocomp_qemu::{f32_le, fail, success, HostFile};

/// Frames per I/O chunk.
const CHUNK_FRAMES: usize = 512;
const FRAME_BYTES: usize = 4 * AXES;

#[entry]
fn main() -> ! {
    let fpscr = cortex_m::register::fpscr::read().bits();
    hprintln!("FPSCR=0x{:08x}", fpscr);

    let mut img_buf = [0u8; MAX_BOX_IMAGE_LEN];
    let n = HostFile::open_read(b"image.dcimg\0").read_full(&mut img_buf);
    let image = match BoxImage::parse(&img_buf[..n]) {
        Ok(i) => i,
        Err(_) => fail("image.dcimg is not a valid coefficient image"),
    };
    let mut states = [AxisState::default(); AXES];
    let mut matrix_state = MimoState::default();
    let mut input = HostFile::open_read(b"input.bin\0");
    let mut output = HostFile::create(b"output.bin\0");
    let mut inb = [0u8; CHUNK_FRAMES * FRAME_BYTES];
    let mut outb = [0u8; CHUNK_FRAMES * FRAME_BYTES];
    let mut frames = 0usize;
    loop {
        let got = input.read_full(&mut inb);
        if !got.is_multiple_of(FRAME_BYTES) {
            fail("input.bin is not a whole number of 3-axis f32 frames");
        }
        if got == 0 {
            break;
        }
        for (fin, fout) in inb[..got].chunks_exact(FRAME_BYTES).zip(outb.chunks_exact_mut(FRAME_BYTES)) {
            let u: [f32; AXES] = core::array::from_fn(|axis| f32_le(&fin[4 * axis..]));
            let y = match &image {
                BoxImage::Matrix(m) => m.filter.step(&mut matrix_state, u),
                BoxImage::PerAxis(img) => core::array::from_fn(|axis| match &img.axes[axis] {
                    Some(a) => a.filter.step(&mut states[axis], u[axis]),
                    None => u[axis],
                }),
            };
            for (axis, v) in y.iter().enumerate() {
                fout[4 * axis..4 * axis + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
        output.write_all(&outb[..got]);
        frames += got / FRAME_BYTES;
    }
    hprintln!("frames={}", frames);
    success()
}
