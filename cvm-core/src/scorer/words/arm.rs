//! The Cortex-M block loops of the word kernels: four words of each map
//! per `LDM` for the squared distance, eight per `LDM`/`STM` pair for the
//! copy.

/// The sum of `squared_difference` over the first `4 * (n / 4)` words
/// (`n` the shorter length) and that number of words: four words of each
/// map per `LDM` (`cvm_squared_difference_4`), 12 instructions per four
/// words instead of about 19 compiled, and a quarter of the bus accesses
/// where a map is in a row buffer.
#[inline(always)]
pub fn squared_difference_blocks(a: &[i32], b: &[i32]) -> (i64, usize) {
    let blocks = a.len().min(b.len()) / 4;
    if blocks == 0 {
        return (0, 0);
    }
    // SAFETY: `a` and `b` hold at least `4 * blocks` words; the function
    // reads exactly those, writes registers only and preserves the
    // callee-saved ones (AAPCS).
    let acc = unsafe { cvm_squared_difference_4(a.as_ptr(), b.as_ptr(), blocks) };
    (acc as i64, 4 * blocks)
}

// `(a, b, blocks) -> Σ (a - b)²` over `4 blocks` words (`blocks > 0`),
// wrapping (see `squared_difference`): r0-r3 hold `a`, `b`, the count
// and the low word, r12 and lr the high word and a spare.
core::arch::global_asm!(
    ".section .text.cvm_squared_difference_4,\"ax\",%progbits",
    ".global cvm_squared_difference_4",
    ".type cvm_squared_difference_4,%function",
    ".p2align 2",
    ".thumb_func",
    "cvm_squared_difference_4:",
    "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
    "    movs r3, #0",
    "    mov r12, #0",
    "1:",
    "    ldm r0!, {{r4, r5, r6, r7}}",
    "    ldm r1!, {{r8, r9, r10, r11}}",
    "    sub r4, r4, r8",
    "    smlal r3, r12, r4, r4",
    "    sub r5, r5, r9",
    "    smlal r3, r12, r5, r5",
    "    sub r6, r6, r10",
    "    smlal r3, r12, r6, r6",
    "    sub r7, r7, r11",
    "    smlal r3, r12, r7, r7",
    "    subs r2, r2, #1",
    "    bne 1b",
    "    mov r0, r3",
    "    mov r1, r12",
    "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
    ".size cvm_squared_difference_4, . - cvm_squared_difference_4",
);

unsafe extern "C" {
    fn cvm_squared_difference_4(a: *const i32, b: *const i32, blocks: usize) -> u64;
}

/// Copies the first `8 * (n / 8)` words of `src` to `dst` (`n` the
/// shorter length), eight per `LDM`/`STM` pair, and returns the words of
/// both past them.
#[inline(always)]
pub fn copy_blocks<'a, 'b>(src: &'a [i32], dst: &'b mut [i32]) -> (&'a [i32], &'b mut [i32]) {
    let blocks = src.len().min(dst.len()) / 8;
    if blocks > 0 {
        // SAFETY: reads `8 blocks` words of `src` and writes as many to
        // `dst`, both at least that long; r0-r5, r12 and lr are
        // declared clobbered.
        unsafe {
            core::arch::asm!(
                "2:",
                "ldm {src}!, {{r0, r1, r2, r3, r4, r5, r12, lr}}",
                "stm {dst}!, {{r0, r1, r2, r3, r4, r5, r12, lr}}",
                "subs {n}, {n}, #1",
                "bne 2b",
                src = inout(reg) src.as_ptr() => _,
                dst = inout(reg) dst.as_mut_ptr() => _,
                n = inout(reg) blocks => _,
                out("r0") _,
                out("r1") _,
                out("r2") _,
                out("r3") _,
                out("r4") _,
                out("r5") _,
                out("r12") _,
                out("lr") _,
                options(nostack)
            );
        }
    }
    (
        src.get(blocks * 8..).unwrap_or(&[]),
        dst.get_mut(blocks * 8..).unwrap_or(&mut []),
    )
}
