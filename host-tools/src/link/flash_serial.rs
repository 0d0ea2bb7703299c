//! `dynocomp flash IMAGE --serial PORT`: upload a coefficient image over the
//! box's USB protocol (docs/protocol.md, "Upload", [`run`]).

use std::path::Path;

use anyhow::{bail, Result};
use dynocomp_core::image::CRC32;
use dynocomp_core::protocol::{Request, Status, MAX_CHUNK};
use dynocomp_core::store::trailing_id;

use crate::link::serial::Link;

/// What an upload achieved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Uploaded {
    /// Image id ([`dynocomp_core::image::CoeffImage::id`]) now running.
    pub image_id: u32,
    /// The box's status after the switch.
    pub status: Status,
}

/// Upload image `bytes` (not checked here) and confirm the switch.
/// `progress` is called with (bytes sent, total).
pub fn upload(link: &mut Link, bytes: &[u8], mut progress: impl FnMut(usize, usize)) -> Result<Uploaded> {
    let crc = CRC32.checksum(bytes);
    let id = trailing_id(bytes);
    // A stream left running by an earlier session would lose samples while
    // the slot is erased; stop it (harmless if none runs).
    link.command(Request::StopStream)?;
    link.stream.clear();
    link.command(Request::UploadBegin { len: bytes.len() as u32, crc })?;
    let mut sent = 0;
    for chunk in bytes.chunks(MAX_CHUNK) {
        link.command(Request::UploadChunk { offset: sent as u32, bytes: chunk })?;
        sent += chunk.len();
        progress(sent, bytes.len());
    }
    link.command(Request::UploadCommit)?;
    let status = link.status()?;
    let active = status.active.map(|a| a.image_id);
    let running = status.image.map(|i| i.id);
    if active != Some(id) || running != Some(id) {
        bail!(
            "box committed the upload but reports active image {} and running image {}, expected {id:#010x}",
            fmt_id(active),
            fmt_id(running)
        );
    }
    Ok(Uploaded { image_id: id, status })
}

fn fmt_id(id: Option<u32>) -> String {
    id.map_or("none".into(), |i| format!("{i:#010x}"))
}

/// `dynocomp flash IMAGE --serial PORT`:
///
/// 1. Read and verify the image file locally (the same checks as the box:
///    CRC, version, ranges, stability, runnable), so a bad file is refused
///    before the box is touched.
/// 2. `UploadBegin { len, crc }` (the box erases its inactive slot), the
///    bytes in [`MAX_CHUNK`]-byte chunks, each acknowledged, then
///    `UploadCommit`: the box reads the slot back, verifies it and switches
///    at a sample boundary ([`upload`]).
/// 3. `GetStatus`: the box must report the new image id as active and
///    running; anything else is an error.
pub fn run(image: &Path, port: &str) -> Result<()> {
    let (bytes, img) = crate::link::flash_probe::read_box_image(image)?;
    let mut link = Link::open(port)?;
    let before = link.status()?;
    eprintln!(
        "box on {port}: firmware {}.{}.{}, running image {} ({})",
        before.firmware[0],
        before.firmware[1],
        before.firmware[2],
        fmt_id(before.image.map(|i| i.id)),
        before.bypass.map_or("compensating".to_string(), |r| format!("bypass: {r}"))
    );
    eprintln!("uploading {} ({} bytes, {} Hz, id {:#010x})", image.display(), bytes.len(), img.fs_hz(), img.id());
    let mut last_pct = usize::MAX;
    let up = upload(&mut link, &bytes, |sent, total| {
        let pct = sent * 100 / total.max(1);
        if pct / 10 != last_pct / 10 || sent == total {
            eprintln!("  {pct:3} % ({sent}/{total} bytes)");
            last_pct = pct;
        }
    })?;
    let slot = up.status.active.map(|a| format!("slot {}, sequence {}", a.slot, a.seq)).unwrap_or_default();
    eprintln!("box verified and switched to image {:#010x} ({slot})", up.image_id);
    Ok(())
}
