//! The batched entry points of [`WideAccumulator`]: many blocks in one call,
//! so that the run-time dispatch, and with it the inlining of the copy and
//! of the bookkeeping into the vector code, happens once per call, not once
//! per block.

use core::fmt;

use nalgebra::Dyn;

use super::copy::InSimd;
#[cfg(target_arch = "x86_64")]
use super::copy::InV4;
use super::WideAccumulator;
use crate::{error::Error, estimate::Block};

/// A batched update stopped at an input it refused: `index` is its
/// position in the batch, `error` what [`WideAccumulator::update`] says of
/// it. Everything before it was taken; it and everything after it were not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rejected {
    /// The position of the refused input in the batch.
    pub index: usize,
    /// Why it was refused.
    pub error: Error,
}

impl fmt::Display for Rejected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "input {} of the batch: {}", self.index, self.error)
    }
}

impl std::error::Error for Rejected {}

impl WideAccumulator {
    /// Adds `blocks` in order, as [`Self::update`] on each would, with the
    /// same sums to the last bit — for a stream that arrives, or can be
    /// gathered, several blocks at a time: the instruction set is
    /// dispatched once per call and the per-block copy and checks run
    /// inlined in the vector code. That saves the dispatch per block, a
    /// few percent at N = 9 to 60 on AVX-512 (BENCHMARKS.md); the
    /// de-interleave of each column-major block stays (see
    /// [`Self::update_rows`] for rows without it).
    ///
    /// # Errors
    /// At the first block that [`Self::update`] would refuse:
    /// [`Rejected`] with its index and `update`'s error. The blocks before
    /// it are taken (as by `update` one at a time), it and the blocks after
    /// it are not: feed `&blocks[index + 1..]` to go on past it.
    pub fn update_many(&mut self, blocks: &[Block<f64, Dyn>]) -> Result<(), Rejected> {
        #[cfg(target_arch = "x86_64")]
        if let pulp::Arch::V4(v4) = self.arch {
            return v4.vectorize(ManyV4 {
                acc: self,
                blocks,
                v4,
            });
        }
        let arch = self.arch;
        arch.dispatch(Many { acc: self, blocks })
    }

    /// The loop of [`Self::update_many`], inlined into its dispatched
    /// function.
    #[inline(always)]
    fn blocks_with<C: super::Copier>(
        &mut self,
        blocks: &[Block<f64, Dyn>],
        copier: &C,
    ) -> Result<(), Rejected> {
        for (index, block) in blocks.iter().enumerate() {
            if let Err(error) = self.push_block(block, copier) {
                return Err(Rejected { index, error });
            }
        }
        Ok(())
    }
}

/// [`WideAccumulator::update_many`] on any instruction set.
struct Many<'a, 'b> {
    acc: &'a mut WideAccumulator,
    blocks: &'b [Block<f64, Dyn>],
}

impl pulp::WithSimd for Many<'_, '_> {
    type Output = Result<(), Rejected>;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, s: S) -> Self::Output {
        self.acc.blocks_with(self.blocks, &InSimd(s))
    }
}

/// [`WideAccumulator::update_many`] with AVX-512 (its three-row copy).
#[cfg(target_arch = "x86_64")]
struct ManyV4<'a, 'b> {
    acc: &'a mut WideAccumulator,
    blocks: &'b [Block<f64, Dyn>],
    v4: pulp::x86::V4,
}

#[cfg(target_arch = "x86_64")]
impl pulp::NullaryFnOnce for ManyV4<'_, '_> {
    type Output = Result<(), Rejected>;

    #[inline(always)]
    fn call(self) -> Self::Output {
        self.acc.blocks_with(self.blocks, &InV4(self.v4))
    }
}
