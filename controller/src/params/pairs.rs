//! Data per unordered pair of fault patterns, in the one packed order the crate uses.

/// Values per unordered pair {i, j}, i ≠ j, of `m` items (fault patterns, units of the policy),
/// stored packed in the order (0,1), (0,2), …, (0,m−1), (1,2), …: the one layout of pair data in
/// the crate (θ_ij, γ_ij, η_ij, the pair filters). (i, j) and (j, i) are the same entry.
#[derive(Debug, Clone, PartialEq)]
pub struct PairTable<T> {
    m: usize,
    values: Vec<T>,
}

/// C(m, 2): the number of pairs of `m` items (the length of a [`PairTable`]).
pub fn pair_count(m: usize) -> usize {
    m * m.saturating_sub(1) / 2
}

/// The packed index of the pair (i, j) of `m` items (either order) in a [`PairTable`]; None
/// when i = j or either is out of range.
pub fn pair_slot(m: usize, i: usize, j: usize) -> Option<usize> {
    let (a, b) = (i.min(j), i.max(j));
    (a != b && b < m).then(|| a * (2 * m - a - 1) / 2 + (b - a - 1))
}

impl<T> PairTable<T> {
    /// The table of `m` items with `f(i, j)` (i < j) for each pair, in packed order.
    pub fn from_fn(m: usize, mut f: impl FnMut(usize, usize) -> T) -> Self {
        let mut values = Vec::with_capacity(pair_count(m));
        for i in 0..m {
            for j in (i + 1)..m {
                values.push(f(i, j));
            }
        }
        Self { m, values }
    }

    /// Number of items the pairs are drawn from.
    pub fn items(&self) -> usize {
        self.m
    }

    /// The value of the pair (i, j) (either order); None when i = j or out of range.
    pub fn get(&self, i: usize, j: usize) -> Option<&T> {
        self.values.get(pair_slot(self.m, i, j)?)
    }

    /// The value of the pair (i, j) (either order), mutably.
    pub fn get_mut(&mut self, i: usize, j: usize) -> Option<&mut T> {
        let k = pair_slot(self.m, i, j)?;
        self.values.get_mut(k)
    }

    /// ((i, j), value) for every pair, i < j, in packed order.
    pub fn iter(&self) -> impl Iterator<Item = ((usize, usize), &T)> + '_ {
        let m = self.m;
        (0..m)
            .flat_map(move |i| ((i + 1)..m).map(move |j| (i, j)))
            .zip(&self.values)
    }

    /// The values in packed order.
    pub fn as_slice(&self) -> &[T] {
        &self.values
    }

    /// The values in packed order, mutably.
    pub fn values_mut(&mut self) -> &mut [T] {
        &mut self.values
    }
}

impl<T> std::ops::Index<(usize, usize)> for PairTable<T> {
    type Output = T;
    /// The value of the pair (i, j); panics when i = j or either is out of range.
    fn index(&self, (i, j): (usize, usize)) -> &T {
        match self.get(i, j) {
            Some(v) => v,
            None => panic!("pair ({i}, {j}) of {} items", self.m),
        }
    }
}

impl<T> std::ops::IndexMut<(usize, usize)> for PairTable<T> {
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut T {
        let m = self.m;
        match self.get_mut(i, j) {
            Some(v) => v,
            None => panic!("pair ({i}, {j}) of {m} items"),
        }
    }
}
