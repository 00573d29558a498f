//! A set of the image's cells, one bit a cell, walked in the cells' order:
//! each pose's work list and the sums it leaves out. As lists of `u32`
//! numbers and a `bool` a cell they were 1.1 MB of a 52-pose replay's peak
//! (a pose takes about 3,700 of its 4,800 cells); as bits, 600 bytes a
//! pose.

/// Cells `0..cells` of a grid, each in the set or not.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(super) struct CellSet {
    words: Vec<u64>,
    /// How many cells are in the set.
    members: usize,
}

impl CellSet {
    /// No cell of a grid of `cells`.
    pub(super) fn empty(cells: usize) -> Self {
        Self {
            words: vec![0; cells.div_ceil(64)],
            members: 0,
        }
    }

    /// Puts cell `k` in the set (it must be of the grid).
    #[inline]
    pub(super) fn insert(&mut self, k: usize) {
        let (word, bit) = (k / 64, 1u64 << (k % 64));
        if self.words[word] & bit == 0 {
            self.words[word] |= bit;
            self.members += 1;
        }
    }

    /// Whether cell `k` is in the set.
    #[inline]
    pub(super) fn contains(&self, k: usize) -> bool {
        self.words
            .get(k / 64)
            .is_some_and(|w| w & (1u64 << (k % 64)) != 0)
    }

    /// How many cells are in the set.
    pub(super) fn len(&self) -> usize {
        self.members
    }

    /// The cells in the set, in order.
    pub(super) fn iter(&self) -> Members<'_> {
        self.iter_from(0)
    }

    /// Calls `f` with each cell of the set in `range`, in order: the walk
    /// of the estimate's loops, word by word (32 M fewer instructions in a
    /// 156-frame replay than [`CellSet::iter`]'s one cell at a time).
    #[inline]
    pub(super) fn for_each_in(&self, range: std::ops::Range<usize>, mut f: impl FnMut(usize)) {
        let end = range.end.min(self.words.len() * 64);
        if range.start >= end {
            return;
        }
        let (first_word, last_word) = (range.start / 64, (end - 1) / 64);
        for (w, &word) in self.words[first_word..=last_word].iter().enumerate() {
            let w = first_word + w;
            let mut bits = word;
            if w == first_word {
                bits &= u64::MAX << (range.start % 64);
            }
            if w == last_word && !end.is_multiple_of(64) {
                bits &= u64::MAX >> (64 - end % 64);
            }
            while bits != 0 {
                f(w * 64 + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
    }

    /// The cells in the set from cell `first` on, in order.
    fn iter_from(&self, first: usize) -> Members<'_> {
        let word = first / 64;
        let bits = self
            .words
            .get(word)
            .map_or(0, |w| w & (u64::MAX << (first % 64)));
        Members {
            words: self.words.get(word + 1..).unwrap_or_default(),
            base: word * 64,
            bits,
        }
    }
}

/// [`CellSet::iter`]: the bits of the word being read not yet given, the
/// first cell of that word, and the words after it. A cell costs a test, a
/// count of zeros and a clear of a bit; the next word is fetched out of
/// line (most words hold several cells).
#[derive(Clone)]
pub(super) struct Members<'a> {
    words: &'a [u64],
    base: usize,
    bits: u64,
}

impl Members<'_> {
    /// The next word that holds a cell; `false` past the last.
    #[cold]
    #[inline(never)]
    fn next_word(&mut self) -> bool {
        while let Some((&word, rest)) = self.words.split_first() {
            self.words = rest;
            self.base += 64;
            if word != 0 {
                self.bits = word;
                return true;
            }
        }
        false
    }
}

impl Iterator for Members<'_> {
    type Item = usize;

    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        if self.bits == 0 && !self.next_word() {
            return None;
        }
        let k = self.base + self.bits.trailing_zeros() as usize;
        self.bits &= self.bits - 1;
        Some(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The set walks exactly the cells put in it, in order, from any cell
    /// on and within any range, on grids that end inside a word and on a
    /// word's edge.
    #[test]
    fn walks_its_cells_in_order_from_anywhere() {
        for cells in [1, 63, 64, 65, 130, 4800] {
            let members: Vec<usize> = (0..cells).filter(|k| (k * 7 + k / 5) % 3 == 0).collect();
            let mut set = CellSet::empty(cells);
            for &k in members.iter().rev() {
                set.insert(k);
                set.insert(k);
            }
            assert_eq!(set.len(), members.len(), "{cells} cells");
            assert_eq!(set.iter().collect::<Vec<_>>(), members, "{cells} cells");
            for first in [0, 1, 63, 64, 65, cells - 1, cells] {
                let from: Vec<usize> = members.iter().copied().filter(|&k| k >= first).collect();
                assert_eq!(
                    set.iter_from(first).collect::<Vec<_>>(),
                    from,
                    "{cells} from {first}"
                );
            }
            for range in [
                0..cells,
                1..cells,
                63..65,
                64..128,
                5..5,
                cells..cells + 9,
                0..cells + 64,
            ] {
                let mut walked = Vec::new();
                set.for_each_in(range.clone(), |k| walked.push(k));
                let within: Vec<usize> = members
                    .iter()
                    .copied()
                    .filter(|k| range.contains(k))
                    .collect();
                assert_eq!(walked, within, "{cells} cells, {range:?}");
            }
            for k in 0..cells + 70 {
                assert_eq!(set.contains(k), members.contains(&k), "cell {k} of {cells}");
            }
        }
        assert_eq!(CellSet::empty(0).iter().next(), None);
        let mut last = CellSet::empty(128);
        last.insert(127);
        assert_eq!(last.iter().collect::<Vec<_>>(), vec![127]);
    }
}
