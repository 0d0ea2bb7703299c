//! The sample path's code in CCM SRAM (issue #16).
//!
//! `memory.x` links the output section `.ccmram_text` (the TIM2 handler,
//! placed with `#[link_section]` in `sampler.rs`, with the kernel inlined
//! into it, and the compiler-builtins it calls) to run at 0x1000_0000, the
//! CCM SRAM on the Cortex-M4's I-bus and D-bus (0 wait states at 170 MHz,
//! RM0440 §2.1.1), and to load from flash (`__siccmtext`). Nothing copies
//! it there but this.
//!
//! The copy runs as cortex-m-rt's `__pre_init`: the first thing the reset
//! handler calls, before `.bss`/`.data` are initialised and before `main`,
//! so no code can run from CCM before it is there (the sample interrupt is
//! enabled much later, by `sampler::start`). cortex-m-rt asks for
//! `__pre_init` in assembly, as no Rust code may run before RAM is
//! initialised: a word copy like the reset handler's own `.data` copy
//! (`memory.x` asserts the three addresses are word aligned), then DSB/ISB
//! so the instruction fetches see the copied code. CCM SRAM is clocked
//! from reset (RCC_AHB1ENR has no enable bit for it; RM0440 §7.4.18).
//!
//! `__pre_init` itself stays in flash (`.text.__pre_init`).

core::arch::global_asm!(
    ".section .text.__pre_init,\"ax\",%progbits",
    ".global __pre_init",
    ".type __pre_init,%function",
    ".thumb_func",
    "__pre_init:",
    "    ldr r0, =__sccmtext",
    "    ldr r1, =__eccmtext",
    "    ldr r2, =__siccmtext",
    "0:  cmp r1, r0",
    "    beq 1f",
    "    ldm r2!, {{r3}}",
    "    stm r0!, {{r3}}",
    "    b 0b",
    "1:  dsb",
    "    isb",
    "    bx lr",
    ".size __pre_init, . - __pre_init",
    ".ltorg",
);
