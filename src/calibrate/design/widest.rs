//! The host's passes over many rows compiled for the widest instruction
//! set the processor has, chosen at run time (`pulp`, as the core's
//! `estimate::wide`; no `target-cpu`, no `unsafe`).
//!
//! Only the vector width changes: Rust never fuses a multiply and an add
//! (no FMA unless asked for), and the kernels run through [`widest`] keep
//! each element's operations and their order, so their results are the
//! baseline build's bit for bit.

/// A kernel [`widest`] runs: its `run` must be `#[inline(always)]` and call
/// only `#[inline(always)]` code, so that it is compiled inside the
/// dispatched function (a closure is not inlined there: it stayed a
/// baseline function).
pub(crate) trait Kernel {
    /// What the kernel returns.
    type Output;
    /// The kernel's arithmetic.
    fn run(self) -> Self::Output;
}

/// `k.run()` compiled inside a function for the widest instruction set
/// available (AVX-512, AVX2, or the baseline).
#[inline(always)]
pub(crate) fn widest<K: Kernel>(k: K) -> K::Output {
    struct Op<K>(K);
    impl<K: Kernel> pulp::WithSimd for Op<K> {
        type Output = K::Output;
        #[inline(always)]
        fn with_simd<S: pulp::Simd>(self, _: S) -> K::Output {
            self.0.run()
        }
    }
    pulp::Arch::new().dispatch(Op(k))
}
