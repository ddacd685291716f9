//! [`Values`]: `f64` values a row holds only sometimes.

/// Values a row holds only sometimes (its joint torques, its
/// equilibrium's `θ`, both in [`crate::calibrate::rows::RowExtra`]): none, or a slice of
/// their own, written over in place when the number is the same. 16 B where
/// the `Vec` they were in was 24 B even when empty.
#[derive(Debug, Clone, Default)]
pub(super) struct Values(Option<Box<[f64]>>);

impl Values {
    /// The values (none: empty).
    pub(super) fn as_slice(&self) -> &[f64] {
        self.0.as_deref().unwrap_or_default()
    }

    /// No values.
    pub(super) fn clear(&mut self) {
        self.0 = None;
    }

    /// `v` as the values (none when `v` is empty).
    pub(super) fn set(&mut self, v: &[f64]) {
        match &mut self.0 {
            _ if v.is_empty() => self.0 = None,
            Some(b) if b.len() == v.len() => b.copy_from_slice(v),
            _ => self.0 = Some(v.into()),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::calibrate::rows::values::Values;

    #[test]
    fn values_are_what_was_set_last() {
        let mut v = Values::default();
        assert!(v.as_slice().is_empty());
        v.set(&[1.0, -2.0]);
        assert_eq!(v.as_slice(), [1.0, -2.0]);
        v.set(&[3.0, 4.0]);
        assert_eq!(v.as_slice(), [3.0, 4.0]);
        v.set(&[5.0]);
        assert_eq!(v.as_slice(), [5.0]);
        v.set(&[]);
        assert!(v.0.is_none());
        v.set(&[6.0]);
        v.clear();
        assert!(v.0.is_none() && v.as_slice().is_empty());
    }
}

#[cfg(test)]
mod size {
    /// What a row costs at 10⁶ rows (the doc of [`crate::calibrate::rows::Row`]).
    #[test]
    fn a_row_is_112_bytes() {
        assert_eq!(core::mem::size_of::<crate::calibrate::rows::Row>(), 112);
    }
}
