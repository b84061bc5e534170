//! The reproducible train/test split: stratified, seeded.
//!
//! Only the ChaCha8 stream of `rand_chacha` is used (its output is fixed by the algorithm, not by
//! a crate version), with a documented draw: for each group in order, a partial Fisher-Yates
//! shuffle of the group's indices `0..n` picks `k` of them for the test set; draw `i` takes
//! index `i + u` with `u` uniform in `0..n - i` by rejection sampling on `next_u64`. The same
//! seed gives the same split on every machine and every later build.

use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A uniform integer in `0..n` (n > 0) by rejection sampling (no modulo bias).
fn below(rng: &mut ChaCha8Rng, n: u64) -> u64 {
    let zone = u64::MAX - (u64::MAX - n + 1) % n;
    loop {
        let v = rng.next_u64();
        if v <= zone {
            return v % n;
        }
    }
}

/// For each of the `groups` (each of `n` members, in order) the sorted indices of the `k`
/// members drawn for the test set, from one ChaCha8 stream seeded with `seed`.
pub fn stratified_test_indices(seed: u64, groups: usize, n: usize, k: usize) -> Vec<Vec<usize>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..groups)
        .map(|_| {
            let mut idx: Vec<usize> = (0..n).collect();
            let k = k.min(n);
            for i in 0..k {
                let j = i + below(&mut rng, (n - i) as u64) as usize;
                idx.swap(i, j);
            }
            let mut t = idx[..k].to_vec();
            t.sort_unstable();
            t
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_split_is_stratified_and_reproducible() {
        let a = stratified_test_indices(7, 9, 21, 7);
        assert_eq!(a, stratified_test_indices(7, 9, 21, 7));
        assert_ne!(a, stratified_test_indices(8, 9, 21, 7));
        for g in &a {
            assert_eq!(g.len(), 7);
            assert!(g.windows(2).all(|w| w[0] < w[1]) && g[6] < 21);
        }
        // groups differ (one stream across groups)
        assert!(a.windows(2).any(|w| w[0] != w[1]));
        // every index is drawn about equally often over many seeds
        let mut count = [0usize; 21];
        for s in 0..600 {
            for i in &stratified_test_indices(s, 1, 21, 7)[0] {
                count[*i] += 1;
            }
        }
        assert!(count.iter().all(|c| (150..=250).contains(c)), "{count:?}");
    }
}
