//! The virtual box ([`VirtualBox`]): a host program that runs the box's own
//! protocol handler, coefficient store (on a simulated NOR flash, optionally
//! persisted to a file), image handoff and sample function over a
//! pseudo-terminal. `dynocomp flash --serial` and `dynocomp stream` talk to it
//! exactly as to a real box; the tests use it for upload, switch, power-cut
//! recovery, rejection of bad images and stream loss.

use std::collections::BTreeSet;
use std::io::Write;

use serialport::SerialPort;
use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result};
use dynocomp_core::handoff::ImageHandoff;
use dynocomp_core::image::BoxImage;
use dynocomp_core::link::{Actions, BoxLink, Telemetry};
use dynocomp_core::protocol::{
    encode_frame, BoxMessage, FrameDecoder, StatusCounters, StreamBatcher, StreamSample, MAX_FRAME,
};
use dynocomp_core::sample::{process_sample, BypassReason, Mode, SampleState};
use dynocomp_core::shell::DEFAULT_FS_HZ;
use dynocomp_core::store::{Layout, Store};
use dynocomp_core::AXES;

use crate::link::serial::Transport;
use crate::link::sim_flash::{CutMode, SimFlash};

/// Firmware version the virtual box reports.
pub const VIRTUAL_FIRMWARE: [u8; 3] = [0, 1, 0];
/// Samples the virtual box synthesises per poll while streaming (before
/// decimation).
pub const SAMPLES_PER_POLL: usize = 256;

/// Why [`VirtualBox::serve`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exit {
    /// The simulated power was cut (a scheduled cut was reached).
    PowerLost,
    /// The transport failed (the other side went away).
    LinkClosed,
}

/// The state of one virtual box: the box's protocol handler
/// (`dynocomp_core::link::BoxLink`), coefficient store
/// (`dynocomp_core::store::Store` on a [`SimFlash`]), image handoff
/// (`dynocomp_core::handoff`) and sample function
/// (`dynocomp_core::sample::process_sample`).
///
/// What it does not model: USB timing and packetisation, the sample path's
/// real-time behaviour (samples are synthesised as fast as the link takes
/// them), and real flash timing. Those need the board. Its status therefore
/// reports no core clock and no interrupt cycle counts (`core_clock_hz` and
/// `isr_cycles_*` = 0: not measured) and no overruns.
pub struct VirtualBox {
    store: Store<SimFlash>,
    link: BoxLink,
    decoder: FrameDecoder,
    /// Two image buffers and the handoff between "USB task" and "interrupt".
    images: [Option<BoxImage>; 2],
    handoff: ImageHandoff,
    boot_reason: BypassReason,
    user_bypass: bool,
    state: SampleState,
    batcher: StreamBatcher,
    sample_index: u32,
    drop: BTreeSet<u32>,
    /// Stream frames dropped on purpose (loss injection).
    pub dropped_frames: u32,
}

impl VirtualBox {
    /// Boot from `flash`; stream frames whose sequence numbers are in `drop`
    /// are never sent (simulated loss on the link).
    pub fn boot(flash: SimFlash, drop: impl IntoIterator<Item = u32>) -> Result<VirtualBox> {
        let mut store = Store::open(flash, Layout::STM32G474RE).map_err(|e| anyhow::anyhow!("simulated flash: {e}"))?;
        let boot = store.boot();
        let (image, boot_reason) = match boot.image {
            Ok(img) => (Some(img), BypassReason::NoImage),
            Err(r) => (None, r),
        };
        Ok(VirtualBox {
            store,
            link: BoxLink::new(),
            decoder: FrameDecoder::new(),
            images: [image, None],
            handoff: ImageHandoff::new(0),
            boot_reason,
            user_bypass: false,
            state: SampleState::default(),
            batcher: StreamBatcher::new(),
            sample_index: 0,
            drop: drop.into_iter().collect(),
            dropped_frames: 0,
        })
    }

    /// Whether the simulated power was cut.
    pub fn power_lost(&mut self) -> bool {
        self.store.flash_mut().is_dead()
    }

    /// A copy of the simulated flash (tests: boot it independently).
    pub fn flash_copy(&mut self) -> SimFlash {
        self.store.flash_mut().copy()
    }

    /// Erase and write operations the simulated flash has performed (tests:
    /// the contents are unchanged while this count is).
    pub fn flash_ops(&mut self) -> u64 {
        self.store.flash_mut().ops()
    }

    /// The image the sample path runs.
    pub fn running(&self) -> Option<&BoxImage> {
        self.images[self.handoff.active()].as_ref()
    }

    fn mode(&self) -> Mode<'_> {
        match self.running() {
            Some(_) if self.user_bypass => Mode::Bypass(BypassReason::User),
            Some(img) => Mode::Compensate(img),
            None => Mode::Bypass(self.boot_reason),
        }
    }

    fn fs_hz(&self) -> u32 {
        self.running().map_or(DEFAULT_FS_HZ, |i| i.fs_hz())
    }

    /// Telemetry without the image (the caller adds it).
    fn telemetry(&self) -> Telemetry<'static> {
        let c = self.state.counters;
        Telemetry {
            firmware: VIRTUAL_FIRMWARE,
            fs_hz: self.fs_hz(),
            // No CPU to count cycles of: 0 = unknown / not measured.
            core_clock_hz: 0,
            bypass: match self.mode() {
                Mode::Compensate(_) => None,
                Mode::Bypass(r) => Some(r),
            },
            image: None,
            counters: StatusCounters {
                samples: c.samples,
                overruns: c.overruns,
                saturated: c.saturated,
                nonfinite_resets: self.state.nonfinite_resets(),
                stream_dropped: 0,
                isr_cycles_last: 0,
                isr_cycles_max: 0,
                isr_cycles_mean: 0,
            },
            stream_next_seq: self.batcher.next_seq(),
        }
    }

    /// Handle received bytes; returns the encoded reply frames. Stops early
    /// (dropping the reply) if the simulated power is cut.
    pub fn receive(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut decoder = std::mem::take(&mut self.decoder);
        for &b in bytes {
            let Some(frame) = decoder.push_byte(b) else { continue };
            let mut act = Actions::default();
            let frame = frame.map(|f| f.to_vec());
            let image = self.running().copied();
            let tel = Telemetry { image: image.as_ref(), ..self.telemetry() };
            let msg = self.link.on_frame(frame.as_deref().map_err(|e| *e), &mut self.store, &tel, &mut act);
            if self.power_lost() {
                break;
            }
            self.apply(act, &mut out);
            push_frame(&mut out, &msg);
        }
        self.decoder = decoder;
        out
    }

    /// What the firmware's USB task does with the handler's actions.
    fn apply(&mut self, act: Actions, out: &mut Vec<u8>) {
        if let Some(on) = act.bypass {
            self.user_bypass = on;
        }
        if act.switch_image {
            // USB task: load the committed image into the spare buffer and
            // hand it over; the "interrupt" takes it at the next sample.
            match (self.store.load_active(), self.handoff.writable()) {
                (Ok(img), Some(i)) => {
                    self.images[i] = Some(img);
                    self.handoff.publish(i);
                }
                (Err(r), _) => self.boot_reason = r,
                (Ok(_), None) => {}
            }
            // The virtual box has no concurrent interrupt: take it now.
            self.sample_boundary();
        }
        if let Some(None) = act.stream {
            if let Some(f) = self.batcher.flush() {
                self.send_stream(out, f);
            }
        }
    }

    /// The interrupt's first step at a sample boundary.
    fn sample_boundary(&mut self) {
        if self.handoff.take().is_some() {
            self.state.reset_filters();
        }
    }

    fn send_stream(&mut self, out: &mut Vec<u8>, f: dynocomp_core::protocol::StreamFrame) {
        if self.drop.contains(&f.seq) {
            self.dropped_frames += 1;
        } else {
            push_frame(out, &BoxMessage::Stream(f));
        }
    }

    /// Run `n` samples of the sample path on a synthetic input (three sines
    /// of different frequencies around mid-scale) and return the encoded
    /// stream frames (if streaming).
    pub fn run_samples(&mut self, n: usize) -> Vec<u8> {
        let mut out = Vec::new();
        let fs = f64::from(self.fs_hz());
        for _ in 0..n {
            self.sample_boundary();
            let k = f64::from(self.sample_index);
            let raw: [u16; AXES] = std::array::from_fn(|i| {
                let f = 50.0 * (i as f64 + 1.0);
                (2048.0 + 900.0 * (2.0 * std::f64::consts::PI * f * k / fs).sin()).round() as u16
            });
            let index = self.sample_index;
            let mode = self.mode();
            let mut state = self.state;
            let (dac, flags) = process_sample(raw, mode, &mut state);
            self.state = state;
            self.sample_index = self.sample_index.wrapping_add(1);
            if let Some(dec) = self.link.streaming() {
                if index.is_multiple_of(u32::from(dec)) {
                    let s = StreamSample { raw, out: dac, flags: flags.0 };
                    if let Some(f) = self.batcher.push(index, dec, s) {
                        self.send_stream(&mut out, f);
                    }
                }
            }
        }
        out
    }

    /// Serve on `port` until the power is cut or the link fails.
    pub fn serve(&mut self, port: &mut dyn Transport) -> Exit {
        let mut buf = [0u8; 4096];
        loop {
            let n = match port.read(&mut buf) {
                Ok(n) => n,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted
                    ) =>
                {
                    0
                }
                Err(_) => return Exit::LinkClosed,
            };
            let mut out = self.receive(&buf[..n]);
            if self.power_lost() {
                return Exit::PowerLost;
            }
            if self.link.streaming().is_some() {
                out.extend(self.run_samples(SAMPLES_PER_POLL));
            } else if n == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
            if !out.is_empty() {
                match port.write_all(&out).and_then(|()| port.flush()) {
                    Ok(()) => {}
                    // Nobody reads (the host went away while streaming):
                    // drop the bytes, as a CDC port without a reader does.
                    Err(e) if matches!(e.kind(), std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock) => {}
                    Err(_) => return Exit::LinkClosed,
                }
            }
        }
    }
}

fn push_frame(out: &mut Vec<u8>, msg: &BoxMessage) {
    let mut buf = [0u8; MAX_FRAME];
    // Every box message fits a frame (protocol tests); nothing to send otherwise.
    if let Ok(n) = encode_frame(msg, &mut buf) {
        out.extend_from_slice(&buf[..n]);
    }
}

/// What the virtual box simulates.
#[derive(Clone, Debug, Default)]
pub struct VirtualBoxOptions {
    /// File holding the simulated flash (created erased if missing).
    pub flash: Option<std::path::PathBuf>,
    /// Cut the simulated power at this flash operation (exit status 3).
    pub power_cut_at_op: Option<u64>,
    /// Stream frames never sent (sequence numbers): simulated link loss.
    pub drop_frames: Vec<u32>,
}

/// Exit status of `dynocomp virtual-box` after a simulated power cut.
pub const POWER_CUT_EXIT: i32 = 3;

/// `dynocomp virtual-box`: open a pseudo-terminal, print `PTY <path>` on
/// stdout, serve until the power is cut (exit 3) or killed.
pub fn run(args: &VirtualBoxOptions) -> Result<i32> {
    let mut flash = match &args.flash {
        Some(p) => SimFlash::g474_slots_file(p)?,
        None => SimFlash::g474_slots(),
    };
    if let Some(op) = args.power_cut_at_op {
        flash.cut_power_at(op, CutMode::Torn(op));
    }
    let mut vbox = VirtualBox::boot(flash, args.drop_frames.iter().copied())?;
    let (mut master, slave) = serialport::TTYPort::pair().context("cannot open a pseudo-terminal")?;
    let name = slave.name().context("pseudo-terminal has no name")?;
    // Keep the slave side open (a pty master reads EIO while no slave is
    // open) through a plain file, which holds no lock, so that the host can
    // open the port exclusively as it would a real box; the virtual box is
    // not a session leader, so the slave does not become its controlling
    // terminal.
    let keep = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&name)
        .with_context(|| format!("{name}: cannot open the pseudo-terminal"))?;
    drop(slave);
    master.set_timeout(Duration::from_millis(2)).context("pseudo-terminal timeout")?;
    println!("PTY {name}");
    std::io::stdout().flush().ok();
    let exit = vbox.serve(&mut master);
    drop(keep);
    Ok(match exit {
        Exit::PowerLost => POWER_CUT_EXIT,
        Exit::LinkClosed => 1,
    })
}

/// Start `dynocomp virtual-box` as a child process (tests and demos):
/// returns the child and the pseudo-terminal path it printed.
pub fn spawn(exe: &Path, args: &[&str]) -> Result<(std::process::Child, String)> {
    use std::io::BufRead;
    let mut child = std::process::Command::new(exe)
        .arg("virtual-box")
        .args(args)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .with_context(|| format!("{}: cannot start the virtual box", exe.display()))?;
    let stdout = child.stdout.take().context("virtual box stdout")?;
    let mut line = String::new();
    std::io::BufReader::new(stdout).read_line(&mut line).context("virtual box did not start")?;
    let path = line
        .trim()
        .strip_prefix("PTY ")
        .map(str::to_string)
        .with_context(|| format!("virtual box printed `{}`", line.trim()))?;
    Ok((child, path))
}
