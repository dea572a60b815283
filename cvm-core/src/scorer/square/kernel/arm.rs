//! The square kernels' inner loops on the Cortex-M: `cvm_square_quads`
//! and `cvm_square_pairs` in hand-written Thumb-2, and `SMMULR`.

/// `quads` (module docs of `kernel`) on the Cortex-M:
/// `cvm_square_quads`, 26 instructions per group of four words where the
/// compiled loop, short of registers for its eight pointers, took about
/// 52.
#[inline(always)]
pub fn quads(top: &[u16], bot: &[u16], g2: usize, outs: [&mut [i32]; 4], (k, m): (u32, i32)) {
    let j2 = top.len();
    let [r00, r01, r10, r11] = outs;
    let fits = g2 > 0
        && 2 * g2 <= j2
        && bot.len() == j2
        && r00.len() >= g2
        && r01.len() >= g2
        && r10.len() >= g2
        && r11.len() >= g2;
    if !fits {
        return;
    }
    let addr = |p: *const u8| p as usize as u32;
    let top_p = top.as_ptr();
    let ctx: [u32; 10] = [
        addr(top_p.cast()),
        addr(top_p.wrapping_add(j2 - 1).cast()),
        addr(bot.as_ptr().cast()).wrapping_sub(addr(top_p.cast())),
        addr(r00.as_ptr().cast()),
        addr(r01.as_ptr().cast()),
        addr(r10.as_ptr().cast()).wrapping_sub(addr(r00.as_ptr().cast())),
        addr(r11.as_ptr().cast()).wrapping_sub(addr(r01.as_ptr().cast())),
        k,
        m as u32,
        g2 as u32,
    ];
    // SAFETY: `g2` groups read `top[..g2]`, `top[j2-g2..]` and the same
    // words of `bot` (both `j2` long, `2 g2 <= j2`), and write the first
    // `g2` words of each of the four output rows (each that long), all
    // checked above; the function preserves the callee-saved registers.
    unsafe { square_arm::cvm_square_quads(&ctx) };
}

/// `round(a b / 2^32)`: one `SMMULR`.
#[inline(always)]
pub fn smmulr(a: i32, b: i32) -> i32 {
    let r: i32;
    // SAFETY: one register-only instruction.
    unsafe {
        core::arch::asm!(
            "smmulr {r}, {a}, {b}",
            r = lateout(reg) r,
            a = in(reg) a,
            b = in(reg) b,
            options(pure, nomem, nostack, preserves_flags)
        );
    }
    r
}

/// `pairs_of_rows` (module docs of `kernel`): `cvm_square_pairs`.
#[inline(always)]
pub fn pairs_of_rows(table: &[i32], z: &mut [i32], pairs: usize) {
    // SAFETY: `table` holds the records of `pairs` pairs of rows, and `z`
    // the `2 pairs` words they write plus every word their groups read
    // (at most two past the block, which `embed` checked it has); the
    // function preserves the callee-saved registers (AAPCS).
    unsafe {
        square_arm::cvm_square_pairs(table.as_ptr(), z.as_mut_ptr(), pairs);
    }
}

mod square_arm {
    // `(table, z, pairs) -> table'`: for each pair of rows `(i, i+1)`,
    // `z[i]` and `z[i+1]` from the record (count, diagonal, groups): one
    // `LDM` of three inputs and one of six coefficients per group, six
    // `SMMLAR`s. Outputs are stored after the group loop, where no later
    // row reads them. r0 the table, r1 the row's first input (pushed with
    // r2, the pairs left, while the groups run), r2 the groups, r3 and lr
    // the two rows' sums, r4-r12 one group.
    core::arch::global_asm!(
        ".section .text.cvm_square_pairs,\"ax\",%progbits",
        ".global cvm_square_pairs",
        ".type cvm_square_pairs,%function",
        ".p2align 2",
        ".thumb_func",
        "cvm_square_pairs:",
        "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
        "1:",
        "    push {{r1, r2}}",
        "    ldm r0!, {{r2, r4}}",
        "    ldr r5, [r1], #4",
        "    smmulr r3, r4, r5",
        "    mov lr, #0",
        "2:",
        "    ldm r1!, {{r4, r5, r6}}",
        "    ldm r0!, {{r7, r8, r9, r10, r11, r12}}",
        "    smmlar r3, r7, r4, r3",
        "    smmlar r3, r8, r5, r3",
        "    smmlar r3, r9, r6, r3",
        "    smmlar lr, r10, r4, lr",
        "    smmlar lr, r11, r5, lr",
        "    smmlar lr, r12, r6, lr",
        "    subs r2, r2, #1",
        "    bne 2b",
        "    pop {{r1, r2}}",
        "    str r3, [r1], #4",
        "    str lr, [r1], #4",
        "    subs r2, r2, #1",
        "    bne 1b",
        "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
        ".size cvm_square_pairs, . - cvm_square_pairs",
    );

    // `(ctx)`: the groups of `quads`. `ctx` holds the top row's first
    // and last sample, the bottom row's offset from the top (bytes), the
    // even-even and even-odd output rows, the odd-even and odd-odd rows'
    // offsets from those (bytes), `k`, `m` and the number of groups. Per
    // group: four `LDRH`, the eight sums and differences (each second one
    // as `s - 2 b`, which needs no spare register), four conversions
    // (`LSL`, `SMMULR`) and four stores.
    core::arch::global_asm!(
        ".section .text.cvm_square_quads,\"ax\",%progbits",
        ".global cvm_square_quads",
        ".type cvm_square_quads,%function",
        ".p2align 2",
        ".thumb_func",
        "cvm_square_quads:",
        "    push {{r4, r5, r6, r7, r8, r9, r10, r11, lr}}",
        "    ldm r0, {{r0, r1, r2, r3, r4, r5, r6, r7, r8, r9}}",
        "1:",
        "    ldrh r10, [r0, r2]",
        "    ldrh r11, [r1, r2]",
        "    ldrh r12, [r0], #2",
        "    ldrh lr, [r1], #-2",
        "    add r12, r12, lr",
        "    sub lr, r12, lr, lsl #1",
        "    add r10, r10, r11",
        "    sub r11, r10, r11, lsl #1",
        "    add r12, r12, r10",
        "    sub r10, r12, r10, lsl #1",
        "    add lr, lr, r11",
        "    sub r11, lr, r11, lsl #1",
        "    lsl r12, r12, r7",
        "    smmulr r12, r12, r8",
        "    lsl r10, r10, r7",
        "    smmulr r10, r10, r8",
        "    lsl lr, lr, r7",
        "    smmulr lr, lr, r8",
        "    lsl r11, r11, r7",
        "    smmulr r11, r11, r8",
        "    str r10, [r3, r5]",
        "    str r12, [r3], #4",
        "    str r11, [r4, r6]",
        "    str lr, [r4], #4",
        "    subs r9, r9, #1",
        "    bne 1b",
        "    pop {{r4, r5, r6, r7, r8, r9, r10, r11, pc}}",
        ".size cvm_square_quads, . - cvm_square_quads",
    );

    unsafe extern "C" {
        pub fn cvm_square_pairs(table: *const i32, z: *mut i32, pairs: usize) -> *const i32;
        pub fn cvm_square_quads(ctx: *const [u32; 10]);
    }
}
