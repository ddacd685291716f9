//! The rows of every group of a [`crate::calibrate::design::Design`], in row order.

/// The rows of every group, in row order: in two flat vectors (a vector
/// per group was 10⁶ allocations for a million configurations), or none
/// when row `g` is group `g`'s one row (a configuration measured once per
/// row, as absolute positions often are: 16 MB fewer at 10⁶ rows).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupRows {
    /// Group `g`'s rows are `rows[start[g]..start[g + 1]]` (both empty:
    /// row `g` alone).
    start: Vec<usize>,
    /// Row indices, by group, ascending within a group.
    rows: Vec<usize>,
    /// Number of rows (and of groups when `start` is empty).
    len: usize,
}

/// The rows of one group ([`GroupRows::of`]): a slice of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GroupOf<'a> {
    /// Rows held.
    Rows(&'a [usize]),
    /// The one row of a group whose index is its own.
    One([usize; 1]),
}

impl std::ops::Deref for GroupOf<'_> {
    type Target = [usize];
    fn deref(&self) -> &[usize] {
        match self {
            Self::Rows(r) => r,
            Self::One(r) => r,
        }
    }
}

impl GroupRows {
    /// The rows of `groups` groups from every row's group; `None` when a
    /// group is not below `groups`.
    pub fn new(group: &[usize], groups: usize) -> Option<Self> {
        let len = group.len();
        if groups == len && group.iter().enumerate().all(|(i, &g)| g == i) {
            return Some(Self {
                start: Vec::new(),
                rows: Vec::new(),
                len,
            });
        }
        let mut start = vec![0_usize; groups + 1];
        for &g in group {
            *start.get_mut(g.checked_add(1)?)? += 1;
        }
        for g in 0..groups {
            start[g + 1] += start[g];
        }
        let mut next = start.clone();
        let mut rows = vec![0; len];
        for (i, &g) in group.iter().enumerate() {
            rows[next[g]] = i;
            next[g] += 1;
        }
        Some(Self { start, rows, len })
    }

    /// Whether row `g` is group `g`'s one row, for every group.
    fn identity(&self) -> bool {
        self.start.is_empty()
    }

    /// Number of groups.
    pub fn groups(&self) -> usize {
        if self.identity() {
            self.len
        } else {
            self.start.len() - 1
        }
    }

    /// The positions of group `g`'s rows in [`GroupRows::all`] (empty past
    /// the last group).
    pub fn range(&self, g: usize) -> std::ops::Range<usize> {
        self.offset(g)..self.offset(g.saturating_add(1))
    }

    /// The position in [`GroupRows::all`] of group `g`'s first row (the
    /// number of rows for `g` past the last group).
    pub fn offset(&self, g: usize) -> usize {
        if self.identity() {
            g.min(self.len)
        } else {
            self.start.get(g).copied().unwrap_or(self.rows.len())
        }
    }

    /// Group `g`'s rows, ascending (none past the last group).
    pub fn of(&self, g: usize) -> GroupOf<'_> {
        if self.identity() {
            match g < self.len {
                true => GroupOf::One([g]),
                false => GroupOf::Rows(&[]),
            }
        } else {
            GroupOf::Rows(&self.rows[self.range(g)])
        }
    }

    /// Every row, group by group.
    pub fn all(&self) -> Vec<usize> {
        if self.identity() {
            (0..self.len).collect()
        } else {
            self.rows.clone()
        }
    }
}
