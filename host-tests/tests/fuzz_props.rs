//! Stable-toolchain equivalents of the fuzz targets (issue 8): the same
//! script decoder and the same invariant checks
//! (`host_tests::fuzz_ops::run`, see its module docs), driven by proptest's
//! random bytes instead of libFuzzer's. `PROPTEST_CASES` sets the number of
//! scripts (default 256); `.ci/props.sh` runs a bounded, larger batch.

use host_tests::fuzz_ops::{decode, run, Stats};
use host_tests::Rng;
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig { max_shrink_iters: 2048, ..ProptestConfig::default() })]

    #[test]
    fn scripts_keep_the_invariants_f64(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        run::<f64>(&decode(&bytes));
    }

    #[test]
    fn scripts_keep_the_invariants_f32(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        run::<f32>(&decode(&bytes));
    }
}

/// The random scripts do reach every branch the invariants are about:
/// accepted and rejected updates, merges and solves, in both types.
#[test]
fn scripts_reach_every_branch() {
    let mut rng = Rng::new(99);
    let mut total = [Stats::default(); 2];
    for _ in 0..300 {
        let len = (rng.next_u64() % 4096) as usize;
        let bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
        let ops = decode(&bytes);
        for (t, s) in [run::<f64>(&ops), run::<f32>(&ops)].into_iter().enumerate() {
            total[t].updates_ok += s.updates_ok;
            total[t].updates_rejected += s.updates_rejected;
            total[t].merges_ok += s.merges_ok;
            total[t].merges_rejected += s.merges_rejected;
            total[t].solves_ok += s.solves_ok;
            total[t].solves_rejected += s.solves_rejected;
        }
    }
    for s in total {
        assert!(s.updates_ok > 0 && s.updates_rejected > 0, "{s:?}");
        assert!(s.merges_ok > 0, "{s:?}");
        assert!(s.solves_ok > 0 && s.solves_rejected > 0, "{s:?}");
    }
    println!("f64 {:?}\nf32 {:?}", total[0], total[1]);
}
