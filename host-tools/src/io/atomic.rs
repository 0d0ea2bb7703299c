//! Atomic output files (DESIGN.md, CLI contract: "no output file left behind").
//! Everything the tool writes goes through [`write_atomic`] (or
//! [`write_pair_atomic`] for two files that must change together): on any
//! error the destination is untouched. A leaf of the chain.

use anyhow::{anyhow, bail, Context, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, SystemTime};
use tempfile::NamedTempFile;

/// How often the write-back thread of [`write_atomic`] flushes the
/// temporary file while it is being written.
///
/// While the content is produced, this second thread flushes what was written
/// so far to the disk, so that the final `fsync` has only the tail left: the
/// disk writes overlap the computation instead of following it (74 MB take
/// 0.10 s of `fsync` on this project's benchmark disk, as long as a whole
/// TDMS → TDMS compensation).
pub const WRITEBACK_PERIOD: Duration = Duration::from_millis(10);

/// The output name that means standard output.
pub const STDOUT: &str = "-";

/// Prefix of every temporary file this module names.
const TMP_PREFIX: &str = ".dynocomp-";
/// Suffix of every temporary file this module names.
const TMP_SUFFIX: &str = ".tmp";

/// Age after which a temporary file whose owner cannot be checked (another
/// machine, container or boot; a system without `/proc`; the naming of
/// older versions) counts as stale: no run of the tool lasts a day.
pub const STALE_AGE: Duration = Duration::from_secs(24 * 3600);

/// Whether `path` is `-`, standard output (or input, for a reader).
pub fn is_stdio(path: &Path) -> bool {
    path.as_os_str() == STDOUT
}

/// The folder of the output `path` (`.` for a bare file name): where its
/// temporary file goes, and the temporary files of writers and passes too
/// large for memory (the disk the user chose for a large output).
pub fn output_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Most symlinks followed when resolving an output (Linux's own limit).
const MAX_SYMLINKS: usize = 40;

/// The file an output `path` really names: symlinks followed to their
/// final target (which may not exist yet: a dangling link is written
/// through). An error for a symlink loop, and for an existing target that
/// is not a regular file (device, FIFO, socket, directory).
pub fn resolve_output(path: &Path) -> Result<PathBuf> {
    // What the path finally opens, magic links included: /dev/stdout is
    // /proc/self/fd/1, whose link text (`pipe:[…]`) names no file.
    if let Ok(meta) = std::fs::metadata(path) {
        if !meta.is_file() {
            bail!(
                "{}: is {}, not a regular file; outputs are regular files, or `-` for standard output",
                path.display(),
                kind_of(&meta.file_type())
            );
        }
    }
    let mut p = path.to_path_buf();
    for _ in 0..MAX_SYMLINKS {
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(p),
            Err(e) => return Err(e).with_context(|| format!("{}: cannot inspect the output", path.display())),
        };
        if meta.file_type().is_symlink() {
            let target = std::fs::read_link(&p).with_context(|| format!("{}: cannot read the link", p.display()))?;
            p = output_dir(&p).join(target);
            continue;
        }
        if !meta.is_file() {
            bail!(
                "{}: is {}, not a regular file; outputs are regular files, or `-` for standard output",
                path.display(),
                kind_of(&meta.file_type())
            );
        }
        return Ok(p);
    }
    bail!("{}: more than {MAX_SYMLINKS} symbolic links (a loop?)", path.display())
}

/// What kind of non-regular file `t` is, for messages.
fn kind_of(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_fifo() {
            return "a FIFO (named pipe)";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a directory"
    } else {
        "a special file"
    }
}

/// Refuse to write an output that is one of the inputs. `outputs` and
/// `inputs` are (name as the user gave it, e.g. `--output`, path) pairs;
/// `-` is skipped. Two paths are the same file when their canonical paths
/// are equal (`./x` and `x`, symlinks) or, both existing, when they have the
/// same device and inode (hard links). The message is one line naming both.
pub fn ensure_not_an_input(outputs: &[(&str, &Path)], inputs: &[(&str, &Path)]) -> Result<()> {
    for (oname, out) in outputs.iter().filter(|(_, p)| !is_stdio(p)) {
        let out_canon = canonical_output(out);
        for (iname, inp) in inputs.iter().filter(|(_, p)| !is_stdio(p)) {
            let same_path = out_canon.is_some() && out_canon == std::fs::canonicalize(inp).ok();
            if same_path || same_inode(out, inp) {
                bail!(
                    "{oname} {} is the same file as {iname} {}: writing it would destroy the input; choose another output",
                    out.display(),
                    inp.display()
                );
            }
        }
    }
    Ok(())
}

/// The canonical path of an output, which may not exist yet: its
/// directory's canonical path joined with its (resolved) file name.
fn canonical_output(path: &Path) -> Option<PathBuf> {
    if let Ok(c) = std::fs::canonicalize(path) {
        return Some(c);
    }
    let target = resolve_output(path).ok()?;
    let dir = std::fs::canonicalize(output_dir(&target)).ok()?;
    Some(dir.join(target.file_name()?))
}

/// Whether `a` and `b` both exist and are the same inode of the same device.
fn same_inode(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (a, b);
        false
    }
}

/// Write `path` atomically with the bytes produced by `write`; `-` writes
/// to standard output.
///
/// The content is written to a temporary file in the destination's directory
/// and renamed over the destination only after it was written and flushed
/// completely. On any error the temporary file is removed and the destination
/// is untouched.
///
/// * **`-`** is standard output: the content goes straight to it, with no
///   temporary file (what reached a pipe cannot be taken back).
/// * **Symlinks** are followed: the final target is replaced, the link
///   stays, and the temporary file goes in the target's directory.
/// * **Special files** (devices, FIFOs, sockets, directories) are refused
///   as outputs: renaming a regular file over `/dev/stdout` would replace
///   the device node and send nothing down the pipe.
/// * **Modes**: a replaced file keeps its permission bits (0o777; no
///   set-id or sticky bit); a new file gets 0o666 less the umask, as any
///   program's new file.
/// * **Interruptions**: temporary files are named
///   `.dynocomp-<tag>-<pid>-<start>-<random>.tmp` and listed while they
///   exist; [`install_signal_cleanup`] removes them on SIGINT and SIGTERM,
///   and every write first removes stale ones in its directory
///   ([`sweep_stale`] says when a file is stale).
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    write_atomic_output(path, |w, _| write(w))
}

/// [`write_atomic`], with the temporary file itself beside the buffered
/// writer over it, for writers that place data at offsets (positioned
/// writes, which do not move the file's cursor). A writer that uses both
/// must flush the buffered one before placing anything after its end.
/// Standard output (`-`) has no file to place data in: refused, see
/// [`write_atomic_output`].
pub fn write_atomic_file(path: &Path, write: impl FnOnce(&mut dyn Write, &File) -> Result<()>) -> Result<()> {
    if is_stdio(path) {
        bail!("`-` (standard output): this output is written in place and needs a file; give a file name");
    }
    write_atomic_output(path, |w, f| match f {
        Some(f) => write(w, f),
        None => Err(anyhow!("internal: no file under a file output")),
    })
}

/// [`write_atomic_file`] for outputs that may also go to standard output
/// (`-`): `write` gets the temporary file when there is one, `None` for
/// standard output (then it must write sequentially through the writer).
pub fn write_atomic_output(path: &Path, write: impl FnOnce(&mut dyn Write, Option<&File>) -> Result<()>) -> Result<()> {
    if is_stdio(path) {
        return write_stdout(|w| write(w, None));
    }
    let staged = Staged::create(path)?;
    staged.fill(|w, f| write(w, Some(f)))?;
    staged.commit()
}

/// Write the bytes of `write` to standard output (no temporary file).
fn write_stdout(write: impl FnOnce(&mut dyn Write) -> Result<()>) -> Result<()> {
    let stdout = std::io::stdout();
    let mut w = BufWriter::with_capacity(1 << 20, stdout.lock());
    write(&mut w).context("standard output: not written")?;
    w.flush().context("standard output: write failed")
}

/// Write `bytes` to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes)?))
}

/// Write two files that must change together (an image and its
/// `<image>.model.json` sidecar): after it returns, either both hold the
/// new contents (`Ok`) or both are as they were (`Err`), whichever single
/// step fails (a write, a full disk, a directory or an immutable file in
/// the way of a rename).
///
/// Both are written and synced to temporary files first; the old `first`
/// is kept under a temporary name (a hard link, else a copy); then `first`
/// and `second` are renamed into place, and if the second rename fails the
/// first is put back. A crash between the two renames (microseconds) leaves
/// the new `first` beside the old `second`; readers of a pair must check
/// that they belong together (the sidecar names its image's id). Standard
/// output is refused.
pub fn write_pair_atomic(
    first: &Path,
    write_first: impl FnOnce(&mut dyn Write) -> Result<()>,
    second: &Path,
    write_second: impl FnOnce(&mut dyn Write) -> Result<()>,
) -> Result<()> {
    if is_stdio(first) || is_stdio(second) {
        bail!("`-` (standard output) cannot take one of two files that are written together; give file names");
    }
    let a = Staged::create(first)?;
    let b = Staged::create(second)?;
    a.fill(|w, _| write_first(w))?;
    b.fill(|w, _| write_second(w))?;
    let backup = a.backup_target()?;
    fault::check(fault::Step::CommitFirst)?;
    let a_target = a.target.clone();
    a.commit()?;
    let second_done = fault::check(fault::Step::CommitSecond).and_then(|()| b.commit());
    match second_done {
        Ok(()) => {
            drop(backup);
            Ok(())
        }
        Err(e) => {
            let restored = match backup {
                Some((bak, _listed)) => bak.persist(&a_target).map_err(|e| e.error),
                None => std::fs::remove_file(&a_target),
            };
            match restored {
                Ok(()) => Err(e.context(format!("{}: left as it was", first.display()))),
                Err(r) => {
                    Err(e
                        .context(format!("{}: could not be put back ({r}); it holds the new content", first.display())))
                }
            }
        }
    }
}

/// [`write_pair_atomic`] with byte contents.
pub fn write_bytes_pair_atomic(first: &Path, first_bytes: &[u8], second: &Path, second_bytes: &[u8]) -> Result<()> {
    write_pair_atomic(first, |w| Ok(w.write_all(first_bytes)?), second, |w| Ok(w.write_all(second_bytes)?))
}

/// Test-only fault injection at the steps of [`write_pair_atomic`] that no
/// test can make fail from outside (the renames after both writes).
mod fault {
    /// A step of a pair write.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Step {
        /// Before the first rename.
        CommitFirst,
        /// Before the second rename.
        CommitSecond,
    }

    #[cfg(test)]
    thread_local! {
        pub static FAIL_AT: std::cell::Cell<Option<Step>> = const { std::cell::Cell::new(None) };
    }

    /// An error if a test asked for `step` to fail.
    pub fn check(step: Step) -> anyhow::Result<()> {
        #[cfg(test)]
        if FAIL_AT.with(|f| f.get()) == Some(step) {
            anyhow::bail!("injected fault at {step:?}");
        }
        let _ = step;
        Ok(())
    }
}

/// An output being written: its temporary file (listed for the signal
/// cleanup), the resolved target, and the mode the result gets.
struct Staged {
    /// The output as the user named it (for messages).
    shown: PathBuf,
    /// Its final target (symlinks followed).
    target: PathBuf,
    tmp: NamedTempFile,
    /// The temporary file's entry in the signal cleanup's list.
    listed: Listed,
    /// Permission bits to give the file before it is renamed (`None`: the
    /// creation mode, 0o666 less the umask).
    mode: Option<u32>,
}

impl Staged {
    /// Resolve `path`, remove stale temporary files beside its target, and
    /// create the temporary file.
    fn create(path: &Path) -> Result<Staged> {
        let target = resolve_output(path)?;
        let dir = output_dir(&target);
        sweep_stale_once(dir);
        let mode = existing_mode(&target);
        let tmp = new_temp(dir)
            .with_context(|| format!("{}: cannot create a temporary file in {}", path.display(), dir.display()))?;
        let listed = Listed::new(tmp.path());
        Ok(Staged { shown: path.to_path_buf(), target, tmp, listed, mode })
    }

    /// Write the content with `write` (write-back running), flush, give it
    /// its mode and sync it.
    fn fill(&self, write: impl FnOnce(&mut dyn Write, &File) -> Result<()>) -> Result<()> {
        let path = &self.shown;
        let file = self.tmp.as_file();
        fill_file(file, path, write)?;
        #[cfg(unix)]
        if let Some(mode) = self.mode {
            use std::os::unix::fs::PermissionsExt;
            file.set_permissions(std::fs::Permissions::from_mode(mode)).with_context(|| {
                format!("{}: cannot keep the mode {mode:o} of the file it replaces", path.display())
            })?;
        }
        file.sync_all().with_context(|| format!("{}: sync failed", path.display()))
    }

    /// The current target kept under a temporary name (`None` if it does
    /// not exist), so that a failed pair write can put it back.
    fn backup_target(&self) -> Result<Option<(tempfile::TempPath, Listed)>> {
        if !self.target.exists() {
            return Ok(None);
        }
        let dir = output_dir(&self.target);
        let link = temp_builder().make_in(dir, |p| std::fs::hard_link(&self.target, p));
        let kept = match link {
            Ok(t) => Ok(t),
            Err(_) => temp_builder().make_in(dir, |p| std::fs::copy(&self.target, p).map(drop)),
        }
        .with_context(|| {
            format!("{}: cannot keep the old file while the new one is put in place", self.shown.display())
        })?;
        let path = kept.into_temp_path();
        let listed = Listed::new(&path);
        Ok(Some((path, listed)))
    }

    /// Rename the temporary file over the target (under the cleanup lock,
    /// so that a signal never removes a file that is being renamed), then
    /// sync the directory.
    fn commit(self) -> Result<()> {
        let Staged { shown, target, tmp, listed, .. } = self;
        let persisted = {
            let mut live = live().lock();
            let persisted = tmp.persist(&target);
            live.retain(|p| *p != listed.0);
            persisted
        };
        persisted
            .map_err(|e| e.error)
            .with_context(|| format!("{}: cannot move the finished file into place", shown.display()))?;
        if let Ok(d) = File::open(output_dir(&target)) {
            let _ = d.sync_all();
        }
        Ok(())
    }
}

/// The permission bits of an existing regular file `target` (without
/// set-id and sticky bits), `None` if it does not exist.
fn existing_mode(target: &Path) -> Option<u32> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::metadata(target).ok().map(|m| m.permissions().mode() & 0o777)
    }
    #[cfg(not(unix))]
    {
        let _ = target;
        None
    }
}

/// Write `file` through a buffered writer with the write-back thread
/// running, and flush; errors name `path`.
fn fill_file(file: &File, path: &Path, write: impl FnOnce(&mut dyn Write, &File) -> Result<()>) -> Result<()> {
    std::thread::scope(|scope| -> Result<()> {
        // A cloned handle shares the open file description, hence its
        // write-back error state: an error the background flush sees is
        // returned from here, never lost to the final sync.
        let (done, until_done) = channel::<()>();
        let writeback = match file.try_clone() {
            Ok(f) => Some(scope.spawn(move || write_back(&f, &until_done))),
            Err(_) => None,
        };
        let written = (|| -> Result<()> {
            let mut w = BufWriter::new(file);
            write(&mut w, file).with_context(|| format!("{}: not written", path.display()))?;
            w.flush().with_context(|| format!("{}: write failed", path.display()))
        })();
        drop(done);
        let synced = match writeback.map(|h| h.join()) {
            Some(Ok(r)) => r.with_context(|| format!("{}: sync failed", path.display())),
            Some(Err(_)) => Err(anyhow!("{}: the write-back thread panicked", path.display())),
            None => Ok(()),
        };
        written.and(synced)
    })
}

/// Flush `file`'s written data to the disk every [`WRITEBACK_PERIOD`] until
/// `until_done` is closed; the first error ends it.
fn write_back(file: &File, until_done: &Receiver<()>) -> std::io::Result<()> {
    loop {
        match until_done.recv_timeout(WRITEBACK_PERIOD) {
            Err(RecvTimeoutError::Timeout) => file.sync_data()?,
            _ => return Ok(()),
        }
    }
}

// ---------------------------------------------------------------------------
// Naming, stale files and the signal cleanup.

/// Who owns a temporary file: the machine-and-namespace tag (8 hex digits
/// of SHA-256 of the boot id and the PID namespace; `0` where unknown), the
/// process id and the process start time (clock ticks since boot; 0 where
/// unknown). A PID alone is reused; with its start time it names one
/// process of one boot.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Owner {
    tag: String,
    pid: u32,
    start: u64,
}

impl Owner {
    /// This process.
    fn me() -> &'static Owner {
        static ME: OnceLock<Owner> = OnceLock::new();
        ME.get_or_init(|| {
            let pid = std::process::id();
            Owner { tag: namespace_tag().unwrap_or_else(|| "0".into()), pid, start: start_time(pid).unwrap_or(0) }
        })
    }

    /// Prefix of this owner's temporary file names.
    fn prefix(&self) -> String {
        format!("{TMP_PREFIX}{}-{}-{}-", self.tag, self.pid, self.start)
    }

    /// The owner encoded in a temporary file name, if it has this module's
    /// naming.
    fn parse(name: &str) -> Option<Owner> {
        let body = name.strip_prefix(TMP_PREFIX)?.strip_suffix(TMP_SUFFIX)?;
        let mut parts = body.splitn(4, '-');
        let tag = parts.next()?;
        let pid = parts.next()?.parse().ok()?;
        let start = parts.next()?.parse().ok()?;
        parts.next()?;
        (tag == "0" || (tag.len() == 8 && tag.bytes().all(|b| b.is_ascii_hexdigit()))).then(|| Owner {
            tag: tag.into(),
            pid,
            start,
        })
    }
}

/// 8 hex digits of SHA-256(boot id, PID namespace) on Linux: the same for
/// every process that sees the same `/proc/<pid>` entries.
fn namespace_tag() -> Option<String> {
    use sha2::Digest;
    let boot = std::fs::read_to_string("/proc/sys/kernel/random/boot_id").ok()?;
    let ns = std::fs::read_link("/proc/self/ns/pid").ok()?;
    let hash = sha2::Sha256::digest(format!("{}|{}", boot.trim(), ns.display()).as_bytes());
    Some(hash.iter().take(4).map(|b| format!("{b:02x}")).collect())
}

/// Start time of process `pid` (clock ticks since boot, field 22 of
/// `/proc/<pid>/stat`), `None` if there is no such process or no `/proc`.
fn start_time(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces.
    let after = &stat[stat.rfind(')')? + 1..];
    after.split_whitespace().nth(19)?.parse().ok()
}

/// A builder of this process's temporary file names.
fn temp_builder() -> tempfile::Builder<'static, 'static> {
    static PREFIX: OnceLock<String> = OnceLock::new();
    let prefix = PREFIX.get_or_init(|| Owner::me().prefix());
    let mut b = tempfile::Builder::new();
    b.prefix(prefix.as_str()).suffix(TMP_SUFFIX).rand_bytes(6);
    b
}

/// A new temporary file in `dir`, created with mode 0o666 less the umask.
fn new_temp(dir: &Path) -> std::io::Result<NamedTempFile> {
    let mut b = temp_builder();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o666));
    }
    b.tempfile_in(dir)
}

/// Whether the temporary file `name` (modified at `mtime`) is stale:
///
/// * named by a process of this machine, boot and PID namespace (same
///   tag): stale when that process (PID and start time) no longer runs;
/// * named elsewhere or by a system without `/proc`, or with the naming of
///   older versions (`.dynocomp-XXXXXX.tmp`): stale when older than
///   [`STALE_AGE`];
/// * any other name: never (not ours).
fn is_stale(name: &str, mtime: Option<SystemTime>, now: SystemTime) -> bool {
    let old = || mtime.and_then(|t| now.duration_since(t).ok()).is_some_and(|age| age > STALE_AGE);
    match Owner::parse(name) {
        Some(o) if o.tag != "0" && o.tag == Owner::me().tag => start_time(o.pid) != Some(o.start),
        Some(_) => old(),
        None => is_legacy_name(name) && old(),
    }
}

/// Whether `name` is a temporary file name of older versions of the tool:
/// `.dynocomp-` + 6 alphanumerics + `.tmp`.
fn is_legacy_name(name: &str) -> bool {
    name.strip_prefix(TMP_PREFIX)
        .and_then(|r| r.strip_suffix(TMP_SUFFIX))
        .is_some_and(|r| r.len() == 6 && r.bytes().all(|b| b.is_ascii_alphanumeric()))
}

/// Remove the stale temporary files ([`is_stale`]) of this tool's naming
/// in `dir`; only regular files are touched, and failures are ignored (the
/// sweep is a courtesy, the write does not depend on it). Returns the
/// names removed.
pub fn sweep_stale(dir: &Path) -> Vec<String> {
    let now = SystemTime::now();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut removed = Vec::new();
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !name.starts_with(TMP_PREFIX) || !name.ends_with(TMP_SUFFIX) {
            continue;
        }
        let Ok(meta) = std::fs::symlink_metadata(e.path()) else { continue };
        if meta.is_file() && is_stale(&name, meta.modified().ok(), now) && std::fs::remove_file(e.path()).is_ok() {
            removed.push(name);
        }
    }
    removed
}

/// [`sweep_stale`] once per directory and process.
fn sweep_stale_once(dir: &Path) {
    static SWEPT: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut swept = SWEPT.lock().unwrap_or_else(|e| e.into_inner());
        if swept.contains(&key) {
            return;
        }
        swept.push(key);
    }
    sweep_stale(dir);
}

/// The temporary files that exist now (removed by the signal cleanup).
struct Live(Mutex<Vec<PathBuf>>);

impl Live {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<PathBuf>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Remove every listed file for which `which` holds, and its entry;
    /// returns how many files were removed.
    fn remove(&self, which: impl Fn(&Path) -> bool) -> usize {
        let mut list = self.lock();
        let mut n = 0;
        list.retain(|p| {
            if !which(p) {
                return true;
            }
            n += usize::from(std::fs::remove_file(p).is_ok());
            false
        });
        n
    }
}

/// An entry of the list of live temporary files, removed from it when
/// dropped (after the file itself, which its owner removes or renames).
struct Listed(PathBuf);

impl Listed {
    fn new(p: &Path) -> Listed {
        live().lock().push(p.to_path_buf());
        Listed(p.to_path_buf())
    }
}

impl Drop for Listed {
    fn drop(&mut self) {
        live().lock().retain(|p| *p != self.0);
    }
}

/// The list of live temporary files.
fn live() -> &'static Live {
    static LIVE: Live = Live(Mutex::new(Vec::new()));
    &LIVE
}

/// Remove the temporary files that exist now; what the signal handler of
/// [`install_signal_cleanup`] does before the process ends. Returns how
/// many were removed.
pub fn remove_live_temporaries() -> usize {
    live().remove(|_| true)
}

/// Remove this process's temporary files when it gets SIGINT or SIGTERM,
/// then end it as the signal would (the exit status says which signal).
/// For the command-line program (call it once from `main`); a library
/// host such as Python keeps its own signal handling and does not call it.
/// A thread waits for the signals; no code runs in a signal handler.
#[cfg(unix)]
pub fn install_signal_cleanup() -> Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals =
        signal_hook::iterator::Signals::new([SIGINT, SIGTERM]).context("cannot install the signal handlers")?;
    std::thread::Builder::new()
        .name("dynocomp-signals".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                remove_live_temporaries();
                let _ = signal_hook::low_level::emulate_default_handler(sig);
                std::process::exit(128 + sig);
            }
        })
        .context("cannot start the signal thread")?;
    Ok(())
}

/// No signals to handle off Unix (Ctrl-C ends the process; the next run's
/// sweep removes what it left).
#[cfg(not(unix))]
pub fn install_signal_cleanup() -> Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    /// Files of this module's naming left in `dir`.
    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(TMP_PREFIX))
            .collect()
    }

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).unwrap().permissions().mode() & 0o7777
    }

    /// A write that lasts several write-back periods (the background flush
    /// runs during it) ends with exactly the bytes written, and no temporary
    /// file beside it.
    #[test]
    fn slow_write_is_complete_with_write_back_running() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let chunk: Vec<u8> = (0..=255u8).cycle().take(1 << 16).collect();
        write_atomic(&path, |w| {
            for k in 0..8u8 {
                w.write_all(&chunk)?;
                w.write_all(&[k])?;
                std::thread::sleep(WRITEBACK_PERIOD * 2);
            }
            Ok(())
        })
        .unwrap();
        let got = std::fs::read(&path).unwrap();
        assert_eq!(got.len(), 8 * (chunk.len() + 1));
        for (k, part) in got.chunks(chunk.len() + 1).enumerate() {
            assert_eq!(&part[..chunk.len()], chunk.as_slice());
            assert_eq!(part[chunk.len()], k as u8);
        }
        assert!(leftovers(dir.path()).is_empty());
    }

    /// A write that fails half way leaves the destination as it was and no
    /// temporary file, and the error names the destination.
    #[test]
    fn failed_write_leaves_destination_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        std::fs::write(&path, b"previous").unwrap();
        let err = write_atomic(&path, |w| {
            w.write_all(&[b'x'; 100_000])?;
            std::thread::sleep(WRITEBACK_PERIOD * 3);
            anyhow::bail!("input line 7: not a number")
        })
        .unwrap_err();
        let msg = format!("{err:#}");
        assert!(msg.contains("out.csv") && msg.contains("line 7"), "{msg}");
        assert_eq!(std::fs::read(&path).unwrap(), b"previous");
        assert!(leftovers(dir.path()).is_empty());
    }

    /// An output that is a symlink (relative, absolute, chained, dangling)
    /// is written through: the target gets the content, the link stays a
    /// link, and the temporary file went in the target's folder.
    #[test]
    fn symlinks_are_written_through() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("data");
        std::fs::create_dir(&sub).unwrap();
        let target = sub.join("real.csv");
        std::fs::write(&target, b"old").unwrap();
        let rel = dir.path().join("rel.csv");
        std::os::unix::fs::symlink("data/real.csv", &rel).unwrap();
        let chain = dir.path().join("chain.csv");
        std::os::unix::fs::symlink(&rel, &chain).unwrap();
        for (link, text) in [(&rel, "one"), (&chain, "two")] {
            write_bytes_atomic(link, text.as_bytes()).unwrap();
            assert!(std::fs::symlink_metadata(link).unwrap().file_type().is_symlink());
            assert_eq!(std::fs::read(&target).unwrap(), text.as_bytes());
        }
        let dangling = dir.path().join("new.csv");
        std::os::unix::fs::symlink("data/created.csv", &dangling).unwrap();
        write_bytes_atomic(&dangling, b"three").unwrap();
        assert_eq!(std::fs::read(sub.join("created.csv")).unwrap(), b"three");
        assert!(std::fs::symlink_metadata(&dangling).unwrap().file_type().is_symlink());
        let looped = dir.path().join("loop");
        std::os::unix::fs::symlink("loop", &looped).unwrap();
        assert!(write_bytes_atomic(&looped, b"x").unwrap_err().to_string().contains("symbolic links"));
        assert!(leftovers(dir.path()).is_empty() && leftovers(&sub).is_empty());
    }

    /// Devices, FIFOs and directories are refused as outputs and stay what
    /// they were; `-` cannot take a positioned writer.
    #[test]
    fn special_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let null = Path::new("/dev/null");
        let e = write_bytes_atomic(null, b"x").unwrap_err().to_string();
        assert!(e.contains("/dev/null") && e.contains("character device"), "{e}");
        assert!(!std::fs::metadata(null).unwrap().is_file());
        let link = dir.path().join("to-null");
        std::os::unix::fs::symlink(null, &link).unwrap();
        assert!(write_bytes_atomic(&link, b"x").unwrap_err().to_string().contains("character device"));
        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        assert!(write_bytes_atomic(&fifo, b"x").unwrap_err().to_string().contains("FIFO"));
        let sub = dir.path().join("sub");
        std::fs::create_dir(&sub).unwrap();
        assert!(write_bytes_atomic(&sub, b"x").unwrap_err().to_string().contains("directory"));
        assert!(std::fs::metadata(&sub).unwrap().is_dir());
        // A pipe behind a /proc magic link, as /dev/stdout is in a pipeline.
        let (reader, _writer) = std::io::pipe().unwrap();
        use std::os::fd::AsRawFd;
        let proc_fd = PathBuf::from(format!("/proc/self/fd/{}", reader.as_raw_fd()));
        let e = write_bytes_atomic(&proc_fd, b"x").unwrap_err().to_string();
        assert!(e.contains("FIFO"), "{e}");
        let e = write_atomic_file(Path::new("-"), |_, _| Ok(())).unwrap_err().to_string();
        assert!(e.contains("standard output"), "{e}");
        assert!(leftovers(dir.path()).is_empty());
    }

    /// The same file under another name (`./x`, a symlink, a hard link) is
    /// refused as an output of its own input; a different file is not.
    #[test]
    fn an_output_equal_to_an_input_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("rec.csv");
        std::fs::write(&rec, b"t_s,fx\n").unwrap();
        let dotted = dir.path().join(".").join("rec.csv");
        let link = dir.path().join("link.csv");
        std::os::unix::fs::symlink(&rec, &link).unwrap();
        let hard = dir.path().join("hard.csv");
        std::fs::hard_link(&rec, &hard).unwrap();
        for out in [&rec, &dotted, &link, &hard] {
            let e = ensure_not_an_input(&[("--output", out)], &[("--coeffs", Path::new("a.dcimg")), ("--input", &rec)])
                .unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains("--output") && msg.contains("--input") && !msg.contains('\n'), "{msg}");
        }
        let other = dir.path().join("out.csv");
        ensure_not_an_input(&[("--output", &other)], &[("--input", &rec)]).unwrap();
        std::fs::write(&other, b"x").unwrap();
        ensure_not_an_input(&[("--output", &other)], &[("--input", &rec)]).unwrap();
        ensure_not_an_input(&[("--output", Path::new("-"))], &[("--input", Path::new("-"))]).unwrap();
    }

    /// A replaced file keeps its mode.
    #[test]
    fn a_replaced_file_keeps_its_mode() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        for m in [0o600, 0o640, 0o755] {
            std::fs::write(&path, b"old").unwrap();
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(m)).unwrap();
            write_bytes_atomic(&path, b"new").unwrap();
            assert_eq!(mode(&path), m);
            assert_eq!(std::fs::read(&path).unwrap(), b"new");
        }
    }

    /// The process's umask, from /proc (the truth the kernel applies).
    fn umask() -> Option<u32> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with("Umask:"))?;
        u32::from_str_radix(line.split_whitespace().nth(1)?, 8).ok()
    }

    /// A new file gets 0o666 less the umask: run in a child of this test
    /// binary with umask 027 (0o640 expected, which the former fixed 0o644
    /// is not) and with this process's umask.
    #[test]
    fn a_new_file_honours_the_umask() {
        if let Ok(dir) = std::env::var("DYNOCOMP_UMASK_CHILD_DIR") {
            let path = Path::new(&dir).join("new.csv");
            write_bytes_atomic(&path, b"x").unwrap();
            assert_eq!(mode(&path), 0o666 & !umask().unwrap());
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let exe = std::env::current_exe().unwrap();
        let status = std::process::Command::new("sh")
            .arg("-c")
            .arg("umask 027; exec \"$0\" --exact io::atomic::tests::a_new_file_honours_the_umask --quiet")
            .arg(&exe)
            .env("DYNOCOMP_UMASK_CHILD_DIR", dir.path())
            .status()
            .unwrap();
        assert!(status.success());
        assert_eq!(mode(&dir.path().join("new.csv")), 0o640);
        let own = dir.path().join("own.csv");
        write_bytes_atomic(&own, b"x").unwrap();
        assert_eq!(mode(&own), 0o666 & !umask().unwrap());
    }

    /// Two writes that succeed give both new files; a fault at either
    /// rename, or a failed write of either, leaves both byte-identical to
    /// before (new or not yet existing), with no stray file.
    #[test]
    fn a_pair_changes_together_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let (img, side) = (dir.path().join("box.dcimg"), dir.path().join("box.dcimg.model.json"));
        write_bytes_pair_atomic(&img, b"image 1", &side, b"sidecar 1").unwrap();
        assert_eq!(
            (std::fs::read(&img).unwrap(), std::fs::read(&side).unwrap()),
            (b"image 1".to_vec(), b"sidecar 1".to_vec())
        );
        let old = |()| (std::fs::read(&img).unwrap(), std::fs::read(&side).unwrap());
        for step in [fault::Step::CommitFirst, fault::Step::CommitSecond] {
            fault::FAIL_AT.with(|f| f.set(Some(step)));
            let e = write_bytes_pair_atomic(&img, b"image 2", &side, b"sidecar 2").unwrap_err();
            fault::FAIL_AT.with(|f| f.set(None));
            assert!(format!("{e:#}").contains("injected"), "{e:#}");
            assert_eq!(old(()), (b"image 1".to_vec(), b"sidecar 1".to_vec()), "{step:?}");
            assert!(leftovers(dir.path()).is_empty(), "{step:?}: {:?}", leftovers(dir.path()));
        }
        let full = || std::io::Error::new(std::io::ErrorKind::StorageFull, "No space left on device");
        let e = write_pair_atomic(&img, |w| Ok(w.write_all(b"image 3")?), &side, |_| Err(full().into())).unwrap_err();
        assert!(format!("{e:#}").contains("No space left"), "{e:#}");
        let e = write_pair_atomic(&img, |_| Err(full().into()), &side, |w| Ok(w.write_all(b"sidecar 3")?)).unwrap_err();
        assert!(format!("{e:#}").contains("No space left"), "{e:#}");
        assert_eq!(old(()), (b"image 1".to_vec(), b"sidecar 1".to_vec()));
        assert!(leftovers(dir.path()).is_empty());
        // A new pair whose second rename fails leaves no first file either.
        let (img2, side2) = (dir.path().join("b.dcimg"), dir.path().join("b.dcimg.model.json"));
        fault::FAIL_AT.with(|f| f.set(Some(fault::Step::CommitSecond)));
        assert!(write_bytes_pair_atomic(&img2, b"i", &side2, b"s").is_err());
        fault::FAIL_AT.with(|f| f.set(None));
        assert!(!img2.exists() && !side2.exists());
        assert!(leftovers(dir.path()).is_empty());
    }

    /// A real fault at the second rename: a directory appears where the
    /// sidecar goes while the image is written. The image is put back.
    #[test]
    fn a_directory_in_the_way_of_the_second_file_puts_the_first_back() {
        let dir = tempfile::tempdir().unwrap();
        let (img, side) = (dir.path().join("box.dcimg"), dir.path().join("box.dcimg.model.json"));
        write_bytes_pair_atomic(&img, b"image 1", &side, b"sidecar 1").unwrap();
        std::fs::set_permissions(&img, std::fs::Permissions::from_mode(0o640)).unwrap();
        std::fs::remove_file(&side).unwrap();
        let e = write_pair_atomic(
            &img,
            |w| {
                std::fs::create_dir(&side)?;
                std::fs::write(side.join("inside"), b"x")?;
                Ok(w.write_all(b"image 2")?)
            },
            &side,
            |w| Ok(w.write_all(b"sidecar 2")?),
        )
        .unwrap_err();
        assert!(format!("{e:#}").contains("left as it was"), "{e:#}");
        assert_eq!(std::fs::read(&img).unwrap(), b"image 1");
        assert_eq!(mode(&img), 0o640);
        assert!(side.is_dir());
        assert!(leftovers(dir.path()).is_empty(), "{:?}", leftovers(dir.path()));
    }

    /// An immutable sidecar (chattr +i; needs root and a file system that
    /// supports it, else the test has nothing to check) cannot be replaced:
    /// the image is put back.
    #[test]
    fn an_immutable_second_file_puts_the_first_back() {
        let dir = tempfile::tempdir().unwrap();
        let (img, side) = (dir.path().join("box.dcimg"), dir.path().join("box.dcimg.model.json"));
        write_bytes_pair_atomic(&img, b"image 1", &side, b"sidecar 1").unwrap();
        let chattr =
            |flag: &str| std::process::Command::new("chattr").arg(flag).arg(&side).status().is_ok_and(|s| s.success());
        if !chattr("+i") {
            eprintln!("chattr +i not available here: nothing to check");
            return;
        }
        let r = write_bytes_pair_atomic(&img, b"image 2", &side, b"sidecar 2");
        chattr("-i");
        assert!(r.is_err());
        assert_eq!(std::fs::read(&img).unwrap(), b"image 1");
        assert_eq!(std::fs::read(&side).unwrap(), b"sidecar 1");
        assert!(leftovers(dir.path()).is_empty());
    }

    /// The stale rule, file by file: a file of a dead process of this
    /// namespace goes, one of a live process stays (its start time must
    /// match), a foreign or legacy one goes only when older than a day, and
    /// a name not of this module's naming is never touched.
    #[test]
    fn stale_temporaries_are_swept_and_live_ones_kept() {
        let me = Owner::me();
        if me.tag == "0" {
            eprintln!("no /proc here: only the age rule applies");
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let mut dead = std::process::Command::new("true").spawn().unwrap();
        let dead_pid = dead.id();
        dead.wait().unwrap();
        let mut alive = std::process::Command::new("sleep").arg("30").spawn().unwrap();
        let alive_start = start_time(alive.id()).unwrap();
        let name = |tag: &str, pid: u32, start: u64| format!("{TMP_PREFIX}{tag}-{pid}-{start}-abc123{TMP_SUFFIX}");
        let day_old = SystemTime::now() - STALE_AGE - Duration::from_secs(60);
        let files = [
            (name(&me.tag, dead_pid, 1234), None, false),
            (name(&me.tag, me.pid, me.start), None, true),
            (name(&me.tag, alive.id(), alive_start), None, true),
            (name(&me.tag, alive.id(), alive_start + 1), None, false),
            (name("0badc0de", 1, 1), None, true),
            (name("0badc0de", 1, 1).replace("abc123", "old001"), Some(day_old), false),
            (format!("{TMP_PREFIX}Ab3xYz{TMP_SUFFIX}"), None, true),
            (format!("{TMP_PREFIX}Qw3xYz{TMP_SUFFIX}"), Some(day_old), false),
            (format!("{TMP_PREFIX}notes{TMP_SUFFIX}"), Some(day_old), true),
        ];
        for (n, mtime, _) in &files {
            let f = File::create(dir.path().join(n)).unwrap();
            if let Some(t) = mtime {
                f.set_modified(*t).unwrap();
            }
        }
        let removed = sweep_stale(dir.path());
        alive.kill().unwrap();
        alive.wait().unwrap();
        for (n, _, kept) in &files {
            assert_eq!(dir.path().join(n).exists(), *kept, "{n}");
            assert_eq!(removed.contains(n), !kept, "{n}");
        }
    }

    /// While a write runs, its temporary file is listed, and removing the
    /// live temporaries (what the signal handler does) removes it.
    #[test]
    fn live_temporaries_are_removed_by_the_cleanup() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        std::fs::write(&path, b"old").unwrap();
        let r = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            assert_eq!(leftovers(dir.path()).len(), 1);
            // Only this test's file: other tests write at the same time.
            assert_eq!(live().remove(|p| p.starts_with(dir.path())), 1);
            assert!(leftovers(dir.path()).is_empty());
            Ok(())
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
    }

    /// SIGTERM and SIGINT to a process that is writing an output: the
    /// process ends by the signal and leaves neither its temporary file nor
    /// a changed output (a child of this test binary does the writing).
    #[test]
    fn a_signal_removes_the_temporary_file() {
        if let Ok(dir) = std::env::var("DYNOCOMP_SIGNAL_CHILD_DIR") {
            install_signal_cleanup().unwrap();
            let _ = write_atomic(&Path::new(&dir).join("out.csv"), |w| {
                w.write_all(&[b'x'; 1 << 20])?;
                std::thread::sleep(Duration::from_secs(60));
                Ok(())
            });
            return;
        }
        for sig in ["TERM", "INT"] {
            let dir = tempfile::tempdir().unwrap();
            std::fs::write(dir.path().join("out.csv"), b"old").unwrap();
            let mut child = std::process::Command::new(std::env::current_exe().unwrap())
                .args(["--exact", "io::atomic::tests::a_signal_removes_the_temporary_file", "--quiet"])
                .env("DYNOCOMP_SIGNAL_CHILD_DIR", dir.path())
                .stdout(std::process::Stdio::null())
                .spawn()
                .unwrap();
            let t0 = std::time::Instant::now();
            while leftovers(dir.path()).is_empty() {
                assert!(t0.elapsed() < Duration::from_secs(30), "the child never started writing");
                std::thread::sleep(Duration::from_millis(20));
            }
            std::thread::sleep(Duration::from_millis(100));
            let killed =
                std::process::Command::new("kill").arg(format!("-{sig}")).arg(child.id().to_string()).status().unwrap();
            assert!(killed.success());
            let status = child.wait().unwrap();
            assert!(!status.success(), "SIG{sig}: {status:?}");
            assert!(leftovers(dir.path()).is_empty(), "SIG{sig}: {:?}", leftovers(dir.path()));
            assert_eq!(std::fs::read(dir.path().join("out.csv")).unwrap(), b"old");
        }
    }
}
