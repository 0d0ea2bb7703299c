//! The box firmware's memory layout, read from its ELF (issue #16): the
//! sample interrupt and everything it can call run from CCM SRAM.
//!
//! Builds the firmware as `cargo firmware` does (release,
//! thumbv7em-none-eabihf, the repository's `memory.x`), then reads the ELF
//! with the LLVM tools that rust-toolchain.toml installs (`llvm-tools`:
//! `llvm-nm`, `llvm-objdump`) and checks:
//! * `TIM2` lies in `.ccmram_text` at 0x1000_0000.. (CCM SRAM, I-bus), and
//!   so does every function it can reach through direct branches (followed
//!   transitively); none of them is a range-extension thunk (which would
//!   jump back to flash) and none branches indirectly (which could not be
//!   followed);
//! * the load image of `.ccmram_text` (`__siccmtext`) lies in FLASH, below
//!   the coefficient slots, and `_stext` (cortex-m-rt's `.text`) after it;
//! * the reset handler calls `__pre_init`, which is the copy of `ccm.rs`
//!   (in flash, not cortex-m-rt's empty default), before `main`.
//!
//! Negative control: the same reachability check started from `main`
//! (which runs from flash) fails.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

const CCM: std::ops::Range<u64> = 0x1000_0000..0x1000_8000;
/// Code flash below the coefficient slots (memory.x).
const FLASH: std::ops::Range<u64> = 0x0800_0000..0x0807_C000;

fn firmware_elf() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The `cargo firmware` alias (.cargo/config.toml), spelled out, in the
    // repository's release profile (LTO): a developer's CARGO_PROFILE_*
    // overrides (a fast local build without LTO) would check a different
    // firmware.
    let mut build = common::firmware_cargo_build(root);
    build.args(["-p", "dynocomp-core", "--features", "firmware", "--bin", "dynocomp-box"]);
    let out = build.output().expect("run cargo to build the firmware");
    assert!(
        out.status.success(),
        "building the firmware failed (is the target installed? `rustup target add thumbv7em-none-eabihf`):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let target_dir = std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from);
    target_dir.join("thumbv7em-none-eabihf/release/dynocomp-box")
}

/// An LLVM tool of the active toolchain (`llvm-tools` component).
fn llvm_tool(name: &str) -> PathBuf {
    let rustc = |args: &[&str]| {
        let out = Command::new("rustc").args(args).output().expect("run rustc");
        String::from_utf8(out.stdout).expect("rustc prints UTF-8")
    };
    let sysroot = rustc(&["--print", "sysroot"]);
    let host = rustc(&["-vV"])
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_string))
        .expect("rustc -vV names the host");
    let path = Path::new(sysroot.trim()).join("lib/rustlib").join(host).join("bin").join(name);
    assert!(
        path.exists(),
        "{} is missing: `rustup component add llvm-tools` (rust-toolchain.toml lists it)",
        path.display()
    );
    path
}

fn run(tool: &Path, args: &[&str]) -> String {
    let out = Command::new(tool).args(args).output().unwrap_or_else(|e| panic!("cannot run {}: {e}", tool.display()));
    assert!(out.status.success(), "{} {args:?} failed:\n{}", tool.display(), String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("UTF-8 output")
}

/// The ELF's symbols: name → address, and the addresses of functions.
struct Symbols {
    by_name: BTreeMap<String, u64>,
    functions: BTreeMap<u64, String>,
}

fn symbols(elf: &Path) -> Symbols {
    let text = run(&llvm_tool("llvm-nm"), &["--defined-only", elf.to_str().unwrap()]);
    let mut s = Symbols { by_name: BTreeMap::new(), functions: BTreeMap::new() };
    for line in text.lines() {
        let mut it = line.split_whitespace();
        let (Some(addr), Some(kind), Some(name)) = (it.next(), it.next(), it.next()) else { continue };
        let Ok(addr) = u64::from_str_radix(addr, 16) else { continue };
        s.by_name.insert(name.to_string(), addr);
        if matches!(kind, "t" | "T") && !name.starts_with('$') {
            s.functions.entry(addr).or_insert_with(|| name.to_string());
        }
    }
    s
}

/// Direct branch targets of function `name` (addresses) and its indirect
/// branches (instructions), from the disassembly.
fn branches(elf: &Path, name: &str) -> (Vec<u64>, Vec<String>) {
    let arg = format!("--disassemble-symbols={name}");
    let text = run(&llvm_tool("llvm-objdump"), &["-d", "--no-show-raw-insn", &arg, elf.to_str().unwrap()]);
    let (mut direct, mut indirect) = (Vec::new(), Vec::new());
    for line in text.lines() {
        // "10000f6e:  \tbl\t0x100010e0 <__udivmoddi4> @ imm = #0x8"
        let Some((addr, insn)) = line.split_once(':') else { continue };
        if u64::from_str_radix(addr.trim(), 16).is_err() {
            continue;
        }
        let mut it = insn.split_whitespace();
        let (Some(mnemonic), operand) = (it.next(), it.next().unwrap_or("")) else { continue };
        let is_branch = mnemonic.starts_with('b')
            && !mnemonic.starts_with("bic")
            && !mnemonic.starts_with("bfc")
            && !mnemonic.starts_with("bfi")
            && !mnemonic.starts_with("bkpt");
        let is_cb = mnemonic.starts_with("cbz") || mnemonic.starts_with("cbnz");
        if is_cb {
            let target = insn.split_whitespace().nth(2).unwrap_or("");
            direct.push(u64::from_str_radix(target.trim_start_matches("0x"), 16).expect("cbz target"));
        } else if is_branch {
            match operand.strip_prefix("0x") {
                Some(hex) => direct.push(u64::from_str_radix(hex, 16).expect("branch target")),
                None if operand == "lr" => {}
                None => indirect.push(insn.trim().to_string()),
            }
        } else if insn.contains("pc,")
            && (mnemonic.starts_with("mov") || mnemonic.starts_with("ldr") || mnemonic.starts_with("pop"))
            && !insn.contains("[pc")
        {
            // `mov pc, rN` / `ldr pc, ...` / `pop {.., pc}`: returns (pop) are fine.
            if !mnemonic.starts_with("pop") {
                indirect.push(insn.trim().to_string());
            }
        }
    }
    (direct, indirect)
}

/// Everything `start` can reach; `Err` lists what is outside `region`, a
/// thunk or an indirect branch.
fn reachable_in(
    elf: &Path,
    syms: &Symbols,
    start: &str,
    region: &std::ops::Range<u64>,
) -> Result<Vec<(String, u64)>, Vec<String>> {
    let mut todo = vec![syms.by_name[start]];
    let mut seen = BTreeSet::new();
    let (mut ok, mut bad) = (Vec::new(), Vec::new());
    while let Some(addr) = todo.pop() {
        if !seen.insert(addr) {
            continue;
        }
        let name = syms.functions.get(&addr).cloned().unwrap_or_else(|| format!("{addr:#x}"));
        if !region.contains(&addr) {
            bad.push(format!("{name} at {addr:#010x} is outside {:#x}..{:#x}", region.start, region.end));
            continue;
        }
        if name.contains("Thunk") {
            bad.push(format!("{name} at {addr:#010x} is a range-extension thunk (a call out of the region)"));
        }
        ok.push((name.clone(), addr));
        let (direct, indirect) = branches(elf, &name);
        bad.extend(indirect.into_iter().map(|i| format!("{name}: indirect branch `{i}` cannot be checked")));
        for t in direct {
            if !region.contains(&t) {
                bad.push(format!("{name} branches to {t:#010x}, outside {:#x}..{:#x}", region.start, region.end));
            } else if syms.functions.contains_key(&t) && t != addr {
                todo.push(t);
            }
        }
    }
    if bad.is_empty() {
        Ok(ok)
    } else {
        Err(bad)
    }
}

#[test]
fn sample_interrupt_runs_from_ccm_sram() {
    let elf = firmware_elf();
    let syms = symbols(&elf);
    let sym = |n: &str| *syms.by_name.get(n).unwrap_or_else(|| panic!("symbol {n} missing from the firmware ELF"));
    let (start, end, load) = (sym("__sccmtext"), sym("__eccmtext"), sym("__siccmtext"));
    eprintln!(
        ".ccmram_text: VMA {start:#010x}..{end:#010x} ({} bytes), LMA {load:#010x}; _stext {:#010x}",
        end - start,
        sym("_stext")
    );
    assert!(CCM.contains(&start) && end <= CCM.end && start < end, ".ccmram_text {start:#x}..{end:#x} not in CCM SRAM");
    assert!(
        FLASH.contains(&load) && load + (end - start) <= sym("_stext"),
        "load image at {load:#x} not in flash before .text"
    );

    let in_ccm = reachable_in(&elf, &syms, "TIM2", &(start..end))
        .unwrap_or_else(|bad| panic!("the sample path leaves CCM SRAM:\n{}", bad.join("\n")));
    for (name, addr) in &in_ccm {
        eprintln!("  {addr:#010x} {name}");
    }
    assert!(in_ccm.iter().any(|(n, a)| n == "TIM2" && *a == sym("TIM2")));

    // The reset handler calls our __pre_init (the copy), from flash, before main.
    let pre_init = sym("__pre_init");
    assert!(FLASH.contains(&pre_init), "__pre_init must run from flash (it fills CCM SRAM)");
    assert_ne!(Some(&pre_init), syms.by_name.get("DefaultPreInit"), "__pre_init is cortex-m-rt's empty default");
    let (calls, _) = branches(&elf, "Reset");
    let at = |a: u64| calls.iter().position(|&t| t == a);
    let (p, m) = (at(pre_init).expect("Reset calls __pre_init"), at(sym("main")).expect("Reset calls main"));
    assert!(p < m, "__pre_init must run before main");
    let (copy, _) = branches(&elf, "__pre_init");
    assert!(!copy.is_empty(), "__pre_init has no copy loop");

    // Negative control: main runs from flash, so the same check fails.
    assert!(reachable_in(&elf, &syms, "main", &(start..end)).is_err(), "the reachability check passes anything");
}
