//! File input/output: FRF (CSV, UFF58, a matrix from several files), signal CSV, atomic writes.

pub use frf_set::{read_frf_arg, read_frf_set, split_frf_list};

pub mod atomic;
pub mod clipping;
pub mod decimal;
pub mod frf_csv;
pub mod frf_set;
pub mod image_file;
pub mod signal;
pub mod signal_csv;
pub mod signal_file;
pub mod spool;
pub mod tdms;
pub mod uff;
pub mod uff_signal;

/// Most characters of input text that one error message shows.
pub const ECHO_CHARS: usize = 120;

/// Text taken from an input file (a channel name, a JSON value quoted by a
/// parser's message) as shown in a one-line error: control characters (a
/// newline, a tab) escaped as `\n`, `\t`, … so the message stays one line,
/// and cut after [`ECHO_CHARS`] characters with the text's length in bytes
/// (a whole file on one line is not echoed whole).
pub fn one_line(s: &str) -> String {
    let mut out = String::new();
    for (n, c) in s.chars().enumerate() {
        if n == ECHO_CHARS {
            out.push_str(&format!("… ({} bytes in all)", s.len()));
            break;
        }
        if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}

/// Read an FRF file: `.csv` as FRF CSV, `.uff` / `.unv` / `.uf` as UFF 58/58b,
/// any other extension by content (a first non-blank line `-1` means UFF).
pub fn read_frf(path: &std::path::Path) -> anyhow::Result<crate::frf::Frf> {
    use anyhow::Context;
    let bytes = std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
    parse_frf(path, &bytes)
}

/// Parse the bytes of the FRF file `path` (read by the caller, e.g. to hash
/// the very bytes that are parsed): the format follows from the extension
/// (`.csv`; `.uff`, `.unv`, `.uf`), otherwise from the content.
pub fn parse_frf(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<crate::frf::Frf> {
    frf_set::parse_frf_file(path, bytes).map(|f| f.frf)
}
