//! A set of Gaussian indices as one bit each: `N / 8` bytes, where the per-pass sets of a large
//! scene used to be `[N]` arrays of flags or indices (6 M Gaussians: 0.75 MB instead of 6 to
//! 24 MB, allocated, filled and scanned every pass).

use rayon::prelude::*;

/// Bits per word.
const WORD: usize = 64;

/// A subset of `0..len` (Gaussian indices), one bit per index.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct GaussianBits {
    /// Bit `i % 64` of word `i / 64` is set when `i` is in the set. `[ceil(len / 64)]`
    words: Vec<u64>,
    /// Size of the universe.
    len: usize,
}

impl GaussianBits {
    /// The empty subset of `0..len`.
    pub fn new(len: usize) -> Self {
        GaussianBits {
            words: vec![0; len.div_ceil(WORD)],
            len,
        }
    }

    /// The indices `i` of `0..len` where `member(i)` holds (evaluated in parallel, in runs of
    /// 64 consecutive indices).
    pub fn from_fn(len: usize, member: impl Fn(usize) -> bool + Sync) -> Self {
        let words = (0..len.div_ceil(WORD))
            .into_par_iter()
            .map(|w| {
                let start = w * WORD;
                (start..(start + WORD).min(len))
                    .filter(|&i| member(i))
                    .fold(0u64, |word, i| word | 1 << (i - start))
            })
            .collect();
        GaussianBits { words, len }
    }

    /// Size of the universe (not of the set).
    pub fn universe(&self) -> usize {
        self.len
    }

    /// Adds `i` (must be below the universe's size).
    #[inline]
    pub fn insert(&mut self, i: usize) {
        self.words[i / WORD] |= 1 << (i % WORD);
    }

    /// Adds every member of `other` (a subset of the same universe).
    pub fn union_with(&mut self, other: &GaussianBits) {
        debug_assert_eq!(self.len, other.len, "subsets of one universe");
        for (word, other) in self.words.iter_mut().zip(&other.words) {
            *word |= other;
        }
    }

    /// True when `i` is in the set.
    #[inline]
    pub fn contains(&self, i: usize) -> bool {
        self.words[i / WORD] >> (i % WORD) & 1 == 1
    }

    /// Number of members.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The members in increasing order.
    pub fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.words.iter().enumerate().flat_map(|(w, &word)| {
            let mut rest = word;
            std::iter::from_fn(move || {
                (rest != 0).then(|| {
                    let bit = rest.trailing_zeros() as usize;
                    rest &= rest - 1;
                    w * WORD + bit
                })
            })
        })
    }

    /// The position of each member in [`GaussianBits::iter`]'s order, in O(len / 64).
    pub fn ranks(&self) -> Ranks<'_> {
        let mut before = Vec::with_capacity(self.words.len());
        let mut total = 0u32;
        for word in &self.words {
            before.push(total);
            total += word.count_ones();
        }
        Ranks { bits: self, before }
    }
}

/// Positions of a [`GaussianBits`]' members in increasing order (a compact renumbering).
#[derive(Debug)]
pub struct Ranks<'a> {
    bits: &'a GaussianBits,
    /// Members in the words before each word. `[words]`
    before: Vec<u32>,
}

impl Ranks<'_> {
    /// The number of members below `i`: the position of `i` among the members when `i` is one.
    #[inline]
    pub fn rank(&self, i: usize) -> u32 {
        let below = self.bits.words[i / WORD] & ((1u64 << (i % WORD)) - 1);
        self.before[i / WORD] + below.count_ones()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn members_order_and_ranks_match_a_plain_list() {
        let len = 1000;
        let member = |i: usize| i % 7 == 3 || i % 64 == 63 || i == 0 || i == len - 1;
        let bits = GaussianBits::from_fn(len, member);
        let listed: Vec<usize> = (0..len).filter(|&i| member(i)).collect();
        assert_eq!(bits.iter().collect::<Vec<_>>(), listed);
        assert_eq!(bits.count(), listed.len());
        let mut inserted = GaussianBits::new(len);
        for &i in listed.iter().rev() {
            inserted.insert(i);
        }
        assert_eq!(inserted, bits);
        let ranks = bits.ranks();
        for (position, &i) in listed.iter().enumerate() {
            assert!(bits.contains(i));
            assert_eq!(ranks.rank(i) as usize, position);
        }
        assert!((0..len).filter(|&i| !member(i)).all(|i| !bits.contains(i)));
    }

    #[test]
    fn a_union_holds_the_members_of_both() {
        let len = 300;
        let a = GaussianBits::from_fn(len, |i| i % 5 == 0);
        let b = GaussianBits::from_fn(len, |i| i % 7 == 0 || i == len - 1);
        let mut union = a.clone();
        union.union_with(&b);
        let either = GaussianBits::from_fn(len, |i| i % 5 == 0 || i % 7 == 0 || i == len - 1);
        assert_eq!(union, either);
    }
}
