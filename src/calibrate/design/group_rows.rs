//! The rows of every group of a [`super::Design`], in row order.

/// The rows of every group, in row order, in two flat vectors (a vector
/// per group was 10⁶ allocations for a million configurations).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroupRows {
    /// Group `g`'s rows are `rows[start[g]..start[g + 1]]`.
    start: Vec<usize>,
    /// Row indices, by group, ascending within a group.
    rows: Vec<usize>,
}

impl GroupRows {
    /// The rows of `groups` groups from every row's group; `None` when a
    /// group is not below `groups`.
    pub fn new(group: &[usize], groups: usize) -> Option<Self> {
        let mut start = vec![0_usize; groups + 1];
        for &g in group {
            *start.get_mut(g.checked_add(1)?)? += 1;
        }
        for g in 0..groups {
            start[g + 1] += start[g];
        }
        let mut next = start.clone();
        let mut rows = vec![0; group.len()];
        for (i, &g) in group.iter().enumerate() {
            rows[next[g]] = i;
            next[g] += 1;
        }
        Some(Self { start, rows })
    }

    /// Number of groups.
    pub fn groups(&self) -> usize {
        self.start.len() - 1
    }

    /// The positions of group `g`'s rows in [`GroupRows::all`] (empty past
    /// the last group).
    pub fn range(&self, g: usize) -> std::ops::Range<usize> {
        self.offset(g)..self.offset(g.saturating_add(1))
    }

    /// The position in [`GroupRows::all`] of group `g`'s first row (the
    /// number of rows for `g` past the last group).
    pub fn offset(&self, g: usize) -> usize {
        self.start.get(g).copied().unwrap_or(self.rows.len())
    }

    /// Group `g`'s rows, ascending (none past the last group).
    pub fn of(&self, g: usize) -> &[usize] {
        &self.rows[self.range(g)]
    }

    /// Every row, group by group.
    pub fn all(&self) -> &[usize] {
        &self.rows
    }
}
