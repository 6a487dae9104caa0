//! Sparse symmetric positive definite systems, solved with faer's supernodal sparse Cholesky.
//! The fill-reducing ordering and the symbolic factorization (elimination tree, supernodes)
//! are computed once per sparsity pattern. The pattern is stored already permuted, and every
//! value's place in it is known, so a numeric factorization only scatters the values and
//! factors: no sorting, no permuting and no allocation per factorization.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::linalg::{SupernodalThreshold, amd};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};

/// A fixed sparsity pattern (lower triangle, duplicates summed) with its symbolic Cholesky,
/// and the storage of the last numeric factor.
pub struct SparsePattern {
    n: usize,
    entries: Vec<(usize, usize)>,
    /// `inverse[i]`: the place of unknown i in the fill-reducing order.
    inverse: Vec<usize>,
    /// The lower triangle of the permuted matrix.
    pattern: SymbolicSparseColMat<usize>,
    /// `slot[k]`: where the value of entry k goes in `values`.
    slot: Vec<usize>,
    values: Vec<f64>,
    symbolic: SymbolicCholesky<usize>,
    factor: Vec<f64>,
    factored: bool,
    /// Scratch of the numeric factorization and of a one-column solve.
    workspace: MemBuffer,
}

impl std::fmt::Debug for SparsePattern {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparsePattern")
            .field("n", &self.n)
            .field("entries", &self.entries.len())
            .field("factor_len", &self.factor.len())
            .finish()
    }
}

/// The numeric factorization failed: the matrix is not positive definite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NotPositiveDefinite;

impl SparsePattern {
    /// The pattern of an `n`×`n` matrix whose lower-triangle entries are `(row, col)` pairs,
    /// in the order their values will be given; duplicates are summed.
    pub fn new(n: usize, entries: &[(usize, usize)]) -> SparsePattern {
        SparsePattern::new_blocked(n, entries, 1)
    }

    /// Like [`Self::new`] for unknowns in blocks of `block` (a pose's x, y, θ). The pattern
    /// is built on the graph of blocks, `block²` times smaller: each block that holds an entry
    /// is kept whole, and the fill-reducing ordering keeps each block's unknowns together.
    pub fn new_blocked(n: usize, entries: &[(usize, usize)], block: usize) -> SparsePattern {
        assert!(
            block > 0 && n.is_multiple_of(block),
            "unknowns come in whole blocks"
        );
        let blocks = n / block;
        let original = block_columns(
            blocks,
            entries.iter().map(|&(row, col)| {
                debug_assert!(row >= col && row < n, "lower triangle only");
                (row / block, col / block)
            }),
        );
        let place = block_amd(&original);
        let permuted = block_columns(
            blocks,
            original.iter().enumerate().flat_map(|(col, rows)| {
                let place = &place;
                rows.iter().map(move |&row| {
                    let (a, b) = (place[row], place[col]);
                    (a.max(b), a.min(b))
                })
            }),
        );
        let inverse: Vec<usize> = (0..n)
            .map(|i| place[i / block] * block + i % block)
            .collect();

        // The lower triangle, column by column: the rest of the diagonal block, then each
        // block below it whole.
        let (mut col_ptr, mut row_idx) = (vec![0], Vec::new());
        for (col, rows) in permuted.iter().enumerate() {
            for d in 0..block {
                row_idx.extend(col * block + d..(col + 1) * block);
                for &row in &rows[1..] {
                    row_idx.extend(row * block..(row + 1) * block);
                }
                col_ptr.push(row_idx.len());
            }
        }
        let slot = entries
            .iter()
            .map(|&(row, col)| {
                let (a, b) = (inverse[row], inverse[col]);
                let (hi, lo) = (a.max(b), a.min(b));
                let (hi_block, lo_block) = (hi / block, lo / block);
                let start = col_ptr[lo];
                if hi_block == lo_block {
                    start + hi - lo
                } else {
                    let k = permuted[lo_block][1..]
                        .binary_search(&hi_block)
                        .expect("every entry's block is in the pattern");
                    start + block - lo % block + k * block + hi % block
                }
            })
            .collect();

        // faer's symbolic analysis with the identity ordering reads the upper triangle
        // (whatever side it is told): the transpose, the blocks above the diagonal first.
        let mut above: Vec<Vec<usize>> = vec![Vec::new(); blocks];
        for (col, rows) in permuted.iter().enumerate() {
            for &row in &rows[1..] {
                above[row].push(col);
            }
        }
        let (mut upper_ptr, mut upper_idx) = (vec![0], Vec::new());
        for (col, rows) in above.iter().enumerate() {
            for d in 0..block {
                for &row in rows {
                    upper_idx.extend(row * block..(row + 1) * block);
                }
                upper_idx.extend(col * block..=col * block + d);
                upper_ptr.push(upper_idx.len());
            }
        }
        let upper = SymbolicSparseColMat::new_checked(n, n, upper_ptr, None, upper_idx);
        // Pose graphs fill in: the supernodal (blocked, dense-kernel) factorization is several
        // times faster than the simplicial one faer's heuristic picks for them.
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_cholesky(
            upper.as_ref(),
            Side::Upper,
            SymmetricOrdering::Identity,
            params,
        )
        .expect("symbolic Cholesky of a valid pattern");
        let workspace = MemBuffer::new(StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]));
        SparsePattern {
            n,
            entries: entries.to_vec(),
            inverse,
            values: vec![0.0; row_idx.len()],
            pattern: SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx),
            slot,
            factor: vec![0.0; symbolic.len_val()],
            symbolic,
            factored: false,
            workspace,
        }
    }

    /// The matrix's dimension (rows = columns).
    pub fn dim(&self) -> usize {
        self.n
    }

    /// The `(row, col)` entries, in the order values are given.
    pub fn entries(&self) -> &[(usize, usize)] {
        &self.entries
    }

    /// Factorizes the matrix with these `values` (one per entry given to [`Self::new`]),
    /// keeping the factor for [`Self::solve`].
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), NotPositiveDefinite> {
        assert_eq!(values.len(), self.slot.len(), "one value per pattern entry");
        self.values.fill(0.0);
        for (&slot, &value) in self.slot.iter().zip(values) {
            self.values[slot] += value;
        }
        let matrix = SparseColMatRef::new(self.pattern.as_ref(), &self.values);
        self.factored = false;
        self.symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                matrix,
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut self.workspace),
                Default::default(),
            )
            .map_err(|_| NotPositiveDefinite)?;
        self.factored = true;
        Ok(())
    }

    /// Solves A x = b with the last factor.
    ///
    /// # Panics
    /// If the last [`Self::factorize`] did not succeed.
    pub fn solve(&mut self, b: &[f64]) -> Vec<f64> {
        self.solve_columns(b, 1)
    }

    /// Solves A X = B for the `columns` right-hand sides in `b` (column-major, `dim()` rows
    /// each) at once with the last factor; X in the same layout.
    ///
    /// # Panics
    /// If the last [`Self::factorize`] did not succeed, or `b` is not `columns` columns.
    pub fn solve_columns(&mut self, b: &[f64], columns: usize) -> Vec<f64> {
        assert!(self.factored, "solve needs a successful factorize");
        assert_eq!(b.len(), self.n * columns, "columns of dim() values");
        let mut permuted = vec![0.0; b.len()];
        for (out, col) in permuted.chunks_mut(self.n).zip(b.chunks(self.n)) {
            for (&place, &value) in self.inverse.iter().zip(col) {
                out[place] = value;
            }
        }
        // One column fits the kept workspace; more need their own scratch.
        let mut wide = (columns > 1).then(|| {
            MemBuffer::new(
                self.symbolic
                    .solve_in_place_scratch::<f64>(columns, Par::Seq),
            )
        });
        LltRef::new(&self.symbolic, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut permuted, self.n, columns),
            Par::Seq,
            MemStack::new(wide.as_mut().unwrap_or(&mut self.workspace)),
        );
        let mut x = vec![0.0; b.len()];
        for (out, col) in x.chunks_mut(self.n).zip(permuted.chunks(self.n)) {
            for (o, &place) in out.iter_mut().zip(&self.inverse) {
                *o = col[place];
            }
        }
        x
    }
}

/// The lower triangle of a block pattern from its `(row, col)` block pairs (duplicates
/// allowed): for each block column, the diagonal block first, then the block rows below it
/// in increasing order.
fn block_columns(blocks: usize, pairs: impl Iterator<Item = (usize, usize)>) -> Vec<Vec<usize>> {
    let mut columns: Vec<Vec<usize>> = (0..blocks).map(|col| vec![col]).collect();
    for (row, col) in pairs {
        // The entries of one block come together: skip the repeats cheaply here.
        if row != col && columns[col].last() != Some(&row) {
            columns[col].push(row);
        }
    }
    for rows in &mut columns {
        rows[1..].sort_unstable();
        rows.dedup();
    }
    columns
}

/// Approximate minimum degree ordering of a block pattern (as [`block_columns`] gives it):
/// the place of each block in the order.
fn block_amd(columns: &[Vec<usize>]) -> Vec<usize> {
    let blocks = columns.len();
    let mut col_ptr = Vec::with_capacity(blocks + 1);
    col_ptr.push(0);
    let mut row_idx = Vec::new();
    for rows in columns {
        row_idx.extend_from_slice(rows);
        col_ptr.push(row_idx.len());
    }
    let graph = SymbolicSparseColMat::new_checked(blocks, blocks, col_ptr, None, row_idx);
    let (mut order, mut place) = (vec![0usize; blocks], vec![0usize; blocks]);
    let mut buffer = MemBuffer::new(amd::order_maybe_unsorted_scratch::<usize>(
        blocks,
        graph.compute_nnz(),
    ));
    amd::order_maybe_unsorted(
        &mut order,
        &mut place,
        graph.as_ref(),
        amd::Control::default(),
        MemStack::new(&mut buffer),
    )
    .expect("AMD ordering of a valid pattern");
    place
}

/// Solves A x = b once, for A given as lower-triangle triplets (duplicates summed), with
/// unknowns in blocks of `block`.
pub fn solve_once(
    n: usize,
    block: usize,
    triplets: &[(usize, usize, f64)],
    b: &[f64],
) -> Result<Vec<f64>, NotPositiveDefinite> {
    let entries: Vec<(usize, usize)> = triplets.iter().map(|&(r, c, _)| (r, c)).collect();
    let values: Vec<f64> = triplets.iter().map(|t| t.2).collect();
    let mut pattern = SparsePattern::new_blocked(n, &entries, block);
    pattern.factorize(&values)?;
    Ok(pattern.solve(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_small_system_with_duplicates() {
        // [[4, 1], [1, 3]] given with the (0,0) entry split in two.
        let x = solve_once(
            2,
            1,
            &[(0, 0, 3.0), (0, 0, 1.0), (1, 0, 1.0), (1, 1, 3.0)],
            &[1.0, 2.0],
        )
        .unwrap();
        assert!((4.0 * x[0] + x[1] - 1.0).abs() < 1e-12 && (x[0] + 3.0 * x[1] - 2.0).abs() < 1e-12);
        assert_eq!(
            solve_once(1, 1, &[(0, 0, -1.0)], &[1.0]).err(),
            Some(NotPositiveDefinite)
        );
    }
}
