//! Work compiled for more than the baseline x86-64 CPU (SSE2), chosen at run time: the
//! release binaries stay portable, and a CPU that has an extension runs a build that uses
//! it. The callers' work is written once, `#[inline(always)]`, and inlined into each build.

/// Defines `$name(work)`: runs `work` compiled with target feature `$feature` when the CPU
/// has it, else as it is.
macro_rules! with_feature {
    ($(#[$doc:meta])* $name:ident, $feature:tt) => {
        $(#[$doc])*
        #[inline(always)]
        pub(crate) fn $name<R>(work: impl FnOnce() -> R) -> R {
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!($feature) {
                #[target_feature(enable = $feature)]
                fn compiled_for_it<R>(work: impl FnOnce() -> R) -> R {
                    work()
                }
                // SAFETY: the CPU has the instructions the function is compiled for, as
                // just checked.
                #[allow(unsafe_code)]
                return unsafe { compiled_for_it(work) };
            }
            work()
        }
    };
}

with_feature!(
    /// With POPCNT (all x86-64 CPUs since 2008): a bit count takes one instruction per
    /// word instead of a dozen (the Hamming distances).
    with_popcnt,
    "popcnt"
);

with_feature!(
    /// With AVX2 (most x86-64 CPUs since 2013): integer sums over windows of pixels run
    /// on vectors twice as wide (the sub-pixel refinements). The floating-point steps stay
    /// the same operations in the same order: AVX2 brings no fused multiply-add, and Rust
    /// fuses nothing by itself.
    with_avx2,
    "avx2"
);
